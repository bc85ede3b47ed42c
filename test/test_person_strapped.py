"""A person with muscles strapped in the exoskeleton (core/person/): the person models from
myo-sim, the placement of the exoskeleton's joints on the person's, the cuffs' spring-dampers
against an independent oracle (MuJoCo's own Jacobians), repeatable trials from the kept start
state, the cuff-force limit, the muscle-drive hook and the cuff forces in the JSON."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import pytest

from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.person.cuffs import CUFFS, cuff_metrics
from exo_ilc_ros.core.person.experiment import StrappedExperiment, beyond_cuff_limit
from exo_ilc_ros.core.person.model import MYOARM_PRUNED_JOINTS, muscle_names, person_spec
from exo_ilc_ros.core.person.strapped import EXO_PREFIX, StrappedArm

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

ELBOW = config_dir() / "myoelbow.yaml"
"""Short trials keep these tests short."""
SHORT = {"trajectory.duration": 1.0, "musculoskeletal.settle_time": 0.0,
         "mass_uncertainty": 0.1}


def _config(**overrides: Any) -> Any:
    return load_config(ELBOW, overrides={**SHORT, **overrides})


def test_myoarm_is_the_right_arm_without_hand_and_the_elbow_model_has_six_muscles() -> None:
    """MyoArm pruned: 15 degrees of freedom (shoulder girdle, glenohumeral, elbow), none of
    the pruned joints, the 24 shoulder and elbow muscles (no wrist or finger muscle), the
    torso fixed (no free joint), contacts off; the elbow model: 2 joints, 6 muscles."""
    arm = person_spec("myoarm").compile()
    joints = {arm.joint(i).name for i in range(arm.njnt)}
    assert arm.nv == 15 and not joints & set(MYOARM_PRUNED_JOINTS)
    assert {"shoulder_elv_r", "elv_angle_r", "shoulder_rot_r", "elbow_flexion_r"} <= joints
    assert all(arm.jnt_type[i] != mujoco.mjtJoint.mjJNT_FREE for i in range(arm.njnt))
    muscles = muscle_names(arm)
    assert len(muscles) == 24 and {"BIClong", "TRIlong", "BRA", "DELT1"} <= set(muscles)
    assert not {"FCR", "ECRL", "PT", "FDP2"} & set(muscles)
    assert arm.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    elbow = person_spec("myoelbow").compile()
    assert elbow.nv == 2 and muscle_names(elbow) == ["TRIlong", "TRIlat", "TRImed", "BIClong",
                                                       "BICshort", "BRA"]


def _anchor(arm: StrappedArm, joint: str) -> tuple[np.ndarray, np.ndarray]:
    model, data = arm.model, arm.data
    mujoco.mj_kinematics(model, data)
    j = model.joint(joint).id
    return np.array(data.xanchor[j]), np.array(data.xaxis[j])


def test_the_exoskeletons_joints_sit_on_the_persons_and_move_by_the_misalignment() -> None:
    """At the start the exoskeleton's shoulder anchor is the person's shoulder centre, its
    elbow anchor the person's elbow centre (the upper arm cut to the humerus: < 1 mm) and its
    elbow axis the person's; a misalignment of (4, -3, 12) mm moves the shoulder anchor by
    exactly that, along the exoskeleton's base axes (x = the elbow axis); a 10 deg turn about
    the upper arm's own axis leaves the elbow where it was and turns the elbow axis by 10 deg.
    The exoskeleton's elbow axis is the person's made normal to the upper arm (the person's is
    4 deg off normal: the carrying angle), so the two axes differ by that."""
    arm = StrappedArm(_config(), np.zeros(3))
    shoulder, _ = _anchor(arm, EXO_PREFIX + "shoulder_flexion")
    person_shoulder = np.array(arm.data.xpos[arm.model.body("r_humerus").id])
    np.testing.assert_allclose(shoulder, person_shoulder, atol=1e-12)
    elbow, axis = _anchor(arm, EXO_PREFIX + "elbow_flexion")
    person_elbow, person_axis = _anchor(arm, "r_elbow_flex")
    assert np.linalg.norm(elbow - person_elbow) < 1e-3 and arm.elbow_offset < 1e-3
    along = (person_elbow - person_shoulder) / np.linalg.norm(person_elbow - person_shoulder)
    normal = person_axis - (person_axis @ along) * along
    np.testing.assert_allclose(axis, normal / np.linalg.norm(normal), atol=1e-12)
    moved = StrappedArm(_config(**{"strapping.misalignment.offset": [4.0, -3.0, 12.0]}),
                        np.zeros(3))
    shifted, x_axis = _anchor(moved, EXO_PREFIX + "shoulder_flexion")
    base = moved.data.xmat[moved.model.body(EXO_PREFIX + "link_2").id].reshape(3, 3)
    np.testing.assert_allclose(base.T @ (shifted - person_shoulder), [0.004, -0.003, 0.012],
                               atol=1e-12)
    assert x_axis @ base[:, 0] == pytest.approx(1.0)
    turned = StrappedArm(_config(**{"strapping.misalignment.rotation": [0.0, 0.0, 10.0]}),
                         np.zeros(3))
    assert turned.elbow_offset == pytest.approx(arm.elbow_offset, abs=1e-9)  # about z: the
    _, turned_axis = _anchor(turned, EXO_PREFIX + "elbow_flexion")  # humerus' own axis
    assert float(turned_axis @ axis) == pytest.approx(np.cos(np.radians(10.0)), abs=1e-12)


def test_cuff_forces_are_the_spring_damper_and_match_mujocos_jacobians() -> None:
    """With the exoskeleton held where it was strapped the cuffs carry nothing; turned away,
    each cuff's force is -K x - B v in the cuff frame (x, v: site displacement and velocity,
    read from MuJoCo's sites and Jacobians), and the generalised forces MuJoCo makes of the
    kernel's xfrc_applied equal J^T (F, T) of the sites (an independent formulation)."""
    config = _config()
    arm = StrappedArm(config, np.zeros(3))
    arm.reset()
    arm.measure()
    np.testing.assert_allclose(arm.wrench, 0.0, atol=1e-9)
    model, data = arm.model, arm.data
    exo = slice(model.nq - 3, model.nq)
    data.qpos[exo] = [0.05, -0.03, 0.08]
    data.qvel[:] = np.linspace(-0.4, 0.5, model.nv)
    arm._fresh = False
    arm.measure()
    k = np.asarray(config["strapping.stiffness"])
    b = np.asarray(config["strapping.damping"])
    expected = np.zeros(model.nv)
    for c, cuff in enumerate(CUFFS):
        se, sp = model.site(f"cuff_{cuff}_exo").id, model.site(f"cuff_{cuff}_person").id
        rotation = data.site_xmat[se].reshape(3, 3)
        jac = [np.zeros((3, model.nv)) for _ in range(4)]
        mujoco.mj_jacSite(model, data, jac[0], jac[1], se)
        mujoco.mj_jacSite(model, data, jac[2], jac[3], sp)
        x = rotation.T @ (data.site_xpos[se] - data.site_xpos[sp])
        v = rotation.T @ ((jac[0] - jac[2]) @ data.qvel)
        np.testing.assert_allclose(arm.wrench[c, :3], k * x + b * v, rtol=1e-9, atol=1e-9)
        torque_on_exo = -rotation @ arm.wrench[c, 3:]
        expected += (jac[0] - jac[2]).T @ (rotation @ -arm.wrench[c, :3]) + \
            (jac[1] - jac[3]).T @ torque_on_exo
    assert np.abs(arm.wrench[:, :3]).max() > 1.0
    qfrc = np.zeros(model.nv)
    for body in range(model.nbody):
        mujoco.mj_applyFT(model, data, data.xfrc_applied[body, :3].copy(),
                          data.xfrc_applied[body, 3:].copy(), data.xipos[body].copy(), body,
                          qfrc)
    np.testing.assert_allclose(qfrc, expected, rtol=1e-9, atol=1e-9)


def test_trials_repeat_bit_for_bit_and_the_cuff_limit_aborts_into_the_hold() -> None:
    """Two runs of trial 1 with the same feed-forward are the same to the last bit (the kept
    start state); the cuff wrench is logged per sample; a cuff-force limit of 2 N aborts the
    trial at the first sample a cuff presses past it and commands the safe hold from there."""
    config = _config(**{"musculoskeletal.settle_time": 0.2})
    experiment = StrappedExperiment(config)
    u_ff = np.zeros_like(experiment.reference.position)
    u_ff[:, 2] = 3.0
    first = experiment.run_trial(u_ff, 1)
    again = experiment.run_trial(u_ff, 1)
    np.testing.assert_array_equal(first.position, again.position)
    np.testing.assert_array_equal(first.cuff_wrench, again.cuff_wrench)
    assert first.cuff_wrench is not None and first.cuff_wrench.shape == (101, 2, 6)
    assert first.aborted_at is None
    limited = StrappedExperiment(config.replace({"safety.cuff_force_limit": [2.0, 2.0]}))
    record = limited.run_trial(u_ff, 1)
    forces = np.linalg.norm(first.cuff_wrench[:, :, :3], axis=2)
    expected = int(np.argmax((forces > 2.0).any(axis=1)))
    assert record.aborted_at == expected
    np.testing.assert_array_equal(record.position[:expected + 1],
                                  first.position[:expected + 1])
    assert beyond_cuff_limit(record.cuff_wrench[expected], [2.0, 2.0]) >= 0
    assert not np.allclose(record.effort[expected:], first.effort[expected:])


def test_cuff_metrics_by_hand() -> None:
    """Peak and RMS |F| and |T| per cuff, non-finite samples left out."""
    wrench = np.zeros((3, 2, 6))
    wrench[0, 0, :3] = [3.0, 4.0, 0.0]  # |F| 5
    wrench[1, 0, :3] = [0.0, 0.0, 1.0]  # |F| 1
    wrench[1, 1, 3:] = [0.0, 2.0, 0.0]  # |T| 2
    wrench[2] = np.nan
    metrics = cuff_metrics(wrench)
    np.testing.assert_allclose(metrics[0], [5.0, np.sqrt(13.0), 0.0, 0.0])
    np.testing.assert_allclose(metrics[1], [0.0, 0.0, 2.0, np.sqrt(2.0)])


class _Tone:
    """A muscle drive of constant excitation, counting its resets."""

    def __init__(self, level: float) -> None:
        self.level = level
        self.resets = 0
        self.calls = 0

    def reset(self, model: Any, data: Any) -> None:
        self.resets += 1

    def __call__(self, model: Any, data: Any, controls: np.ndarray) -> None:
        self.calls += 1
        controls[:] = self.level


def test_the_muscle_drive_hook_sets_every_muscles_control_at_every_step() -> None:
    """The drive is called once per MuJoCo step with the muscles' controls, reset at every
    trial's start; its excitation raises the muscles' activation."""
    tone = _Tone(0.5)
    config = _config()
    arm = StrappedArm(config, np.zeros(3), lambda c, m: tone)
    before = tone.resets
    arm.begin_trial(1)
    assert tone.resets == before + 1
    calls = tone.calls
    arm.measure()
    arm.step(np.zeros(3))
    assert tone.calls - calls == arm.substeps
    muscles = [arm.model.actuator(m).id for m in arm.muscles]
    np.testing.assert_array_equal(arm.data.ctrl[muscles], 0.5)
    assert np.all(arm.data.act[:len(muscles)] > 0.0)


def test_bad_strapping_keys_are_refused_naming_the_key() -> None:
    with pytest.raises(ConfigError, match=r"strapping\.elbow_joint"):
        StrappedArm(_config(**{"strapping.elbow_joint": "wrist"}), np.zeros(3))
    with pytest.raises(ConfigError, match=r"safety\.cuff_force_limit"):
        _config(**{"safety.cuff_force_limit": [150.0]})
    with pytest.raises(ConfigError, match=r"musculoskeletal\.model"):
        _config(**{"musculoskeletal.model": "myohand"})
    with pytest.raises(ConfigError, match=r"strapping\.stiffness"):
        _config(**{"strapping.stiffness": [1.0, -1.0, 1.0]})


@pytest.mark.graph
def test_the_graph_runs_the_same_trials_as_simulate() -> None:
    """`exo-ilc run` with a person strapped in: plant_simulator steps the same strapped model
    (its kept start state reset between trials), so three 1 s trials through the real graph
    are the in-process trials (max |e| per trial and joint to 1e-9 rad)."""
    from exo_ilc_ros.core.session.learning_session import run_trials
    from exo_ilc_ros.orchestration.graph import run_graph

    config = load_config(ELBOW, overrides={"trajectory.duration": 1.0, "max_trials": 3,
                                           "mass_uncertainty": 0.1,
                                           "musculoskeletal.settle_time": 0.2})
    local = run_trials(config)
    graph = run_graph(config, timeout=300.0)
    assert [s.trial for s in graph.summaries] == [1, 2, 3]
    np.testing.assert_allclose(graph.summary.max_abs_error, local.max_abs_errors,
                               rtol=0.0, atol=1e-9)
    assert not np.allclose(local.max_abs_errors[0], local.max_abs_errors[-1])  # it learned


def test_cuff_forces_go_into_the_json_and_come_back() -> None:
    """A run's cuff metrics per trial and cuff are written under trials[].cuff_forces with
    their units in the names, and read back exactly; a run without a person has none."""
    from exo_ilc_ros.core.session.summary import CUFF_METRICS, RunSummary

    cuffs = np.arange(2 * 2 * 4, dtype=float).reshape(2, 2, 4) / 3.0
    summary = RunSummary(0.1, "sign", 0.005, np.full((2, 3), 0.1), cuff_forces=cuffs)
    data = summary.to_json()
    assert data["trials"][1]["cuff_forces"]["forearm"] == dict(zip(CUFF_METRICS, cuffs[1, 1],
                                                                    strict=True))
    assert set(data["trials"][0]["cuff_forces"]) == set(CUFFS)
    back = RunSummary.from_json(data)
    assert back.cuff_forces is not None
    np.testing.assert_array_equal(back.cuff_forces, cuffs)
    plain = RunSummary(0.1, "sign", 0.005, np.full((2, 3), 0.1))
    assert "cuff_forces" not in plain.to_json()["trials"][0]
    assert RunSummary.from_json(plain.to_json()).cuff_forces is None


def test_a_config_without_a_person_keeps_its_digest() -> None:
    """The strapping keys count in a digest (the store's key of learned data) only with a
    person: the shipped config's digest is the one it had before they existed, and every one
    of them is in the schema's group that is left out."""
    from exo_ilc_ros.core.params import schema
    from exo_ilc_ros.core.params.schema.musculoskeletal import musculoskeletal_parameters

    assert {p.name for p in musculoskeletal_parameters()} == set(schema.STRAPPED_KEYS)
    plain = load_config()
    assert not set(schema.STRAPPED_KEYS) & set(plain.identity_values())
    moved = plain.replace({"strapping.stiffness": [1.0, 2.0, 3.0],
                           "safety.cuff_force_limit": [10.0, 10.0]})
    assert moved.digest() == plain.digest()
    person = load_config(ELBOW)
    # every strapping key but the body size, which counts only when it scales (its default,
    # the model's own size, keeps the digests of before: test_body_size.py)
    assert set(schema.STRAPPED_KEYS) - {"musculoskeletal.body_size"} <= \
        set(person.identity_values())
    assert person.replace({"strapping.stiffness": [1.0, 2.0, 3.0]}).digest() != person.digest()
