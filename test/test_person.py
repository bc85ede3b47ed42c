"""A person in the exoskeleton through the config (``person.*``, core/arm/build.py) and the
virtual patient's joints mapped onto a URDF arm's (``patient.joints``, core/loop/patient.py):
the plant's mass matrix against Pinocchio with the segments added as bodies, the nominal model
without them, each scenario effect on its named joint only, clear errors, and a Panda with a
person that the learning takes up."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from test_urdf_chain import _pinocchio

from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.arm.body_segments import segment_inertial
from exo_ilc_ros.core.arm.build import build_arm, build_plant, person_segments
from exo_ilc_ros.core.arm.joint_forces import REST, STIFFNESS, VISCOUS, passive_effort_into
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.loop.patient import PatientModel, spasticity_values
from exo_ilc_ros.core.params.config import config_dir
from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm

CONFIG = config_dir()
PANDA = CONFIG / "arms" / "panda.yaml"
PERSON = CONFIG / "person.yaml"
FINGERS = {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.02}


def _panda_pinocchio(with_person_of: object = None) -> tuple[pin.Model, pin.Data]:
    """Pinocchio's Panda (fingers locked at 0.02 m) and, given a config, each of its person's
    segments appended as a body to the joint that moves its link."""
    model, _ = _pinocchio((CONFIG.parent / "urdf" / "panda.urdf").read_text(), FINGERS)
    if with_person_of is not None:
        segments, placements = person_segments(with_person_of)  # type: ignore[arg-type]
        for segment in segments:
            placement = placements[segment.name]
            frame = model.frames[model.getFrameId(placement.link)]
            mass, com, inertia = segment_inertial(segment, placement)
            body = pin.Inertia(mass, com, inertia)  # in the link's frame, about the com
            model.appendBodyToJoint(frame.parentJoint, body, frame.placement)
    return model, model.createData()


def _random_states(model: pin.Model, count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    return [rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
            for _ in range(count)]


def test_the_person_changes_the_plants_mass_matrix_by_exactly_the_segments() -> None:
    """Plant (person in) and nominal (person out) against Pinocchio's Panda with and without
    the segments as bodies: each mass matrix, and so their difference, the segments' share."""
    config = load_config(PANDA, overlays=[PERSON])
    assert config["person.enabled"] and not config["person.in_nominal"]
    plant, nominal = build_plant(config.with_mass_uncertainty(0.0)), build_arm(config)
    with_model, with_data = _panda_pinocchio(config)
    bare_model, bare_data = _panda_pinocchio()
    for q in _random_states(bare_model, 6):
        m_with = pin.crba(with_model, with_data, q)
        m_bare = pin.crba(bare_model, bare_data, q)
        m_with, m_bare = np.triu(m_with) + np.triu(m_with, 1).T, \
            np.triu(m_bare) + np.triu(m_bare, 1).T
        scale = float(np.max(np.abs(m_with)))
        assert np.max(np.abs(plant.metric_tensor(q) - m_with)) < 1e-12 * scale
        assert np.max(np.abs(nominal.metric_tensor(q) - m_bare)) < 1e-12 * scale
        share = plant.metric_tensor(q) - nominal.metric_tensor(q)
        assert np.max(np.abs(share - (m_with - m_bare))) < 1e-12 * scale
        assert np.max(np.abs(share)) > 1e-2 * scale  # the person is not negligible
        zero = np.zeros(7)
        g_with = pin.rnea(with_model, with_data, q, zero, zero)
        assert np.max(np.abs(plant.bias_forces(q, zero) - g_with)) < 1e-11 * np.max(
            np.abs(g_with))


def test_person_in_nominal_and_mass_error_leave_the_person_unscaled() -> None:
    """person.in_nominal puts the segments in the nominal model too; the plant's mass error
    scales the robot, not the person: plant(delta) - plant(0) = delta x robot."""
    config = load_config(PANDA, overlays=[PERSON])
    with_nominal = config.replace({"person.in_nominal": True})
    q = np.array(config["trajectory.start"])
    assert np.allclose(build_arm(with_nominal).metric_tensor(q),
                       build_plant(config.with_mass_uncertainty(0.0)).metric_tensor(q),
                       rtol=0, atol=1e-14)
    robot = load_config(PANDA)
    change = (build_plant(config.with_mass_uncertainty(0.1)).metric_tensor(q)
              - build_plant(config.with_mass_uncertainty(0.0)).metric_tensor(q))
    expected = 0.1 * build_arm(robot).metric_tensor(q)
    assert np.allclose(change, expected, rtol=1e-12, atol=1e-14)


def test_the_cone_arm_refuses_a_person() -> None:
    """The paper's cone links are the person's arm: nothing to strap a person to."""
    with pytest.raises(ConfigError) as err:
        load_config(overlays=[PERSON])
    assert err.value.key == "person.enabled" and "the paper's arm" in err.value.rule


def test_person_errors_name_the_key() -> None:
    config = load_config(PANDA, overlays=[PERSON])
    with pytest.raises(ConfigError) as err:
        config.replace({"person.forearm.sagittal_axis": [0.0, 1.0, 0.0]})  # along the forearm
    assert err.value.key == "person.forearm.sagittal_axis" and "normal" in err.value.rule
    bad_link = config.replace({"person.hand.link": "panda_link9"})
    with pytest.raises(ConfigError) as err:
        build_plant(bad_link)
    assert err.value.key == "person.hand.link" and "'panda_link9' is not a link" in \
        err.value.rule
    with pytest.raises(ConfigError) as err:
        build_plant(config.replace({"person.upper_arm.link": "panda_link0"}))
    assert err.value.key == "person.upper_arm.link" and "fixed to the base" in err.value.rule


def test_a_scenario_acts_on_the_named_arm_joints_only() -> None:
    """friction and spastic on the Panda: every effect on joints 2, 1, 4 (the mapping's order:
    shoulder flexion, abduction, elbow), none on 3, 5, 6, 7; the rest position from the joint
    zero, the elbow's sign flipped."""
    friction = PatientModel(load_config(PANDA, overlays=[CONFIG / "scenarios" / "friction.yaml"]))
    mapped, unmapped = [1, 0, 3], [2, 4, 5, 6]
    assert np.allclose(friction.joint[VISCOUS, mapped], 0.14)
    assert np.all(friction.joint[:, unmapped] == 0.0)
    assert np.allclose(friction.joint[STIFFNESS, mapped], 1.0)
    # rest [0, 0, 0.3] (the patient's angles) from joint_zero [-0.785, 0, -2.356], elbow "-":
    assert np.allclose(friction.joint[REST, mapped], [-0.785, 0.0, -2.356 - 0.3])
    spastic = load_config(PANDA, overlays=[CONFIG / "scenarios" / "spastic.yaml"])
    stiffness, _, gain, _, _ = spasticity_values(spastic)
    assert [stiffness[j] for j in mapped] == [4.0] * 3 and [stiffness[j] for j in unmapped] \
        == [0.0] * 4
    assert [gain[j] for j in unmapped] == [0.0] * 4 and gain[3] == 1.0


def test_the_patients_torque_along_a_trial_is_on_the_mapped_joints_only() -> None:
    """The passive joint forces (friction, stiffness, spastic damping) of a Panda trial under
    friction then spastic, at every sample of the trial: non-zero on panda_joint2, 1 and 4,
    exactly zero on the others."""
    config = load_config(PANDA, overlays=[CONFIG / "scenarios" / "friction.yaml",
                                          CONFIG / "scenarios" / "spastic.yaml"])
    record = run_trials(config, mass_uncertainty=0.1, trials=1).records[0]
    patient = PatientModel(config)
    inverse_stribeck = 1.0 / config["patient.friction.stribeck_velocity"]
    torque = np.zeros_like(record.position)
    for i in range(record.position.shape[0]):
        passive_effort_into(record.position[i], record.velocity[i], np.zeros(7), patient.joint,
                            inverse_stribeck, torque[i])
    peak = np.max(np.abs(torque), axis=0)
    assert np.all(peak[[1, 0, 3]] > 0.1)
    assert np.all(peak[[2, 4, 5, 6]] == 0.0)


@pytest.mark.parametrize("mapping, rule", [
    ("shoulder_flexion: panda_joint2, shoulder_abduction: panda_joint1, "
     "elbow_flexion: panda_joint9", "'elbow_flexion' acts on 'panda_joint9', which is not"),
    ("shoulder_flexion: panda_joint2, shoulder_abduction: panda_joint1, "
     "elbow_flexion: -panda_joint2", "'panda_joint2' is given to two"),
    ("shoulder_flexion panda_joint2", "is not 'patient_joint: arm_joint'"),
])
def test_a_bad_mapping_names_the_joint(mapping: str, rule: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(PANDA, overrides={"patient.joints": mapping, "patient.joint_zero": 0.0})
    assert err.value.key == "patient.joints" and rule in err.value.rule


def test_a_scenario_without_a_mapping_says_how_to_map() -> None:
    with pytest.raises(ConfigError) as err:
        load_config(PANDA, overlays=[CONFIG / "scenarios" / "friction.yaml"],
                    overrides={"patient.joints": "", "patient.joint_zero": 0.0})
    assert "patient.joints maps them" in str(err.value)


def test_the_learning_takes_up_a_person_the_nominal_model_leaves_out() -> None:
    """Panda at 10 % mass error with a 75 kg person in the plant, not in the nominal model:
    the first trial misses by far, and within 12 trials every joint is within 0.005 rad
    (measured: trial 11; the person's own share of the error is what trial 1 shows)."""
    config = load_config(PANDA, overlays=[PERSON])
    result = run_trials(config, mass_uncertainty=0.10, trials=12)
    errors = result.max_abs_errors
    assert np.min(errors[0]) > 0.1
    assert np.all(errors[-1] <= 0.005)
    bare = run_trials(load_config(PANDA), mass_uncertainty=0.10, trials=1)
    assert np.max(errors[0]) > 2 * np.max(bare.max_abs_errors[0])  # measured: 0.66 vs 0.26 rad


def test_the_mujoco_plant_carries_the_person() -> None:
    """MuJoCo's plant (``--plant mujoco``) from the same config: its mass matrix and bias forces
    with the person equal our plant's, and differ from the robot alone by the person."""
    config = load_config(PANDA, overlays=[PERSON])
    mujoco_plant = MujocoArm.from_config(config.with_mass_uncertainty(0.1))
    plant = build_plant(config.with_mass_uncertainty(0.1))
    q = np.array(config["trajectory.start"]) + 0.1
    qd = np.full(7, 0.2)
    mass, bias = mujoco_plant.inertia_and_bias(q, qd)
    a = plant.metric_tensor(q)
    assert np.max(np.abs(mass - a)) < 1e-12 * np.max(np.abs(a))
    c = plant.bias_forces(q, qd)
    assert np.max(np.abs(bias - c)) < 1e-12 * np.max(np.abs(c))
    robot = build_plant(load_config(PANDA).with_mass_uncertainty(0.1)).metric_tensor(q)
    assert np.max(np.abs(mass - robot)) > 1e-2 * np.max(np.abs(a))
