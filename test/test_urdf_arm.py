"""A config's arm from its URDF (model.source: urdf): the paper's arm through `exo-ilc urdf` gives
the cone arm's trials, digests and keys take the URDF's contents (not its path), a per-joint key
takes one value for every joint, the shipped Panda learns within 10 trials at 10 %, and a wrong
URDF or reference is one clear error line through `exo-ilc simulate`."""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest
import yaml
from test_urdf_chain import MASSLESS_FOREARM, TWO_JOINTS

from exo_ilc_ros.analysis.figures import convergence_figure
from exo_ilc_ros.bag.view import ArmView
from exo_ilc_ros.cli.main import main as cli_main
from exo_ilc_ros.core import run_trials
from exo_ilc_ros.core.arm.build import (
    build_arm,
    person_segments,
    urdf_chain,
    urdf_joint_dynamics,
    view_urdf,
)
from exo_ilc_ros.core.arm.dynamics import inertia_and_bias
from exo_ilc_ros.core.arm.forward_kinematics import UrdfKinematics
from exo_ilc_ros.core.arm.joint_forces import REST
from exo_ilc_ros.core.arm.mujoco_urdf import MujocoUrdfArm
from exo_ilc_ros.core.arm.urdf import arm_urdf
from exo_ilc_ros.core.arm.urdf_chain import read_urdf_chain
from exo_ilc_ros.core.convergence.growth import fit_growth
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.learning.norm_optimal_model import MODEL_KEYS, _key
from exo_ilc_ros.core.loop.patient import PatientModel
from exo_ilc_ros.core.loop.stepper import PlantStepper
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.core.persistence.profile_format import model_values
from exo_ilc_ros.core.persistence.store import learning_key
from exo_ilc_ros.core.reference.build import build_reference
from exo_ilc_ros.core.session.summary import RunSummary
from exo_ilc_ros.core.sim.experiment import Experiment
from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm

ROOT = Path(__file__).resolve().parents[1]
ARMS = ROOT / "config" / "arms"


def _arm_yaml(path: Path, model: dict[str, Any], shared: dict[str, Any] | None = None) -> Path:
    """An arm file: ``model.*`` and shared keys over the gains every arm file sets."""
    params: dict[str, Any] = {"model": model, "control": {"kp": 16.0, "kd": 8.0},
                              "safety": {"hold_kp": 225.0, "hold_kd": 30.0}}
    params.update(shared or {})
    schedule = {"position": {"threshold_low": 1.5, "threshold_high": 20.0, "level_mid": 0.03,
                             "level_high": 0.9},
                "velocity": {"threshold_low": 0.1, "threshold_high": 0.2, "level_high": 0.01},
                "acceleration": {"threshold_low": 0.1, "level_high": 0.01}}
    path.write_text(yaml.safe_dump({
        "/**": {"ros__parameters": params},
        "ilc_supervisor": {"ros__parameters": {"law": "linear", "schedule": schedule}}}))
    return path


def _paper_arm_as_urdf(directory: Path) -> Path:
    """The shipped arm through `exo-ilc urdf`, and a config naming that file."""
    urdf = directory / "exo_arm.urdf"
    assert cli_main(["urdf", "--out", str(urdf)]) == 0
    config = directory / "arm.yaml"
    config.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"model": {
        "source": "urdf", "urdf": urdf.name, "base_link": "base_link",
        "tip_link": "forearm_link"}}}}))
    return config


def test_paper_arm_from_its_urdf_gives_the_same_trials(tmp_path: Path) -> None:
    """joint_names and effort limits come from the URDF (the writer wrote the config's), the
    trials equal the cone arm's to 1e-12 (sign law, 5 %, and the linear law, 15 %)."""
    cones = load_config()
    urdf = load_config(_paper_arm_as_urdf(tmp_path))
    assert urdf["model.source"] == "urdf" and Path(urdf["model.urdf"]).is_absolute()
    assert urdf["joint_names"] == cones["joint_names"]
    assert urdf["control.effort_limit"] == cones["control.effort_limit"]
    arm = build_arm(urdf)
    assert arm.position_upper is not None and arm.velocity_limit is not None
    for law, delta in (("sign", 0.05), ("linear", 0.15)):
        a = run_trials(cones, delta, 4, law=law)
        b = run_trials(urdf, delta, 4, law=law)
        for ra, rb in zip(a.records, b.records, strict=True):
            np.testing.assert_allclose(rb.position, ra.position, rtol=0, atol=1e-12)
            np.testing.assert_allclose(rb.feedforward, ra.feedforward, rtol=0, atol=1e-12)
            np.testing.assert_allclose(rb.effort, ra.effort, rtol=0, atol=1e-12)


def test_keys_take_the_urdf_contents_not_its_path(tmp_path: Path) -> None:
    first = load_config(_paper_arm_as_urdf(tmp_path))
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    shutil.copy(tmp_path / "exo_arm.urdf", moved / "exo_arm.urdf")
    shutil.copy(tmp_path / "arm.yaml", moved / "arm.yaml")
    second = load_config(moved / "arm.yaml")
    assert first["model.urdf"] != second["model.urdf"]
    reference = build_reference(first)
    assert first.digest() == second.digest()
    assert learning_key(first, reference) == learning_key(second, reference)
    assert _key(first, MODEL_KEYS) == _key(second, MODEL_KEYS)
    assert model_values(first) == model_values(second)
    assert model_values(first)["model.urdf"] == "sha256:" + first.urdf_digest
    cones = load_config()
    assert first.digest() != cones.digest()
    assert "model.urdf" not in model_values(cones)  # a cone arm's keys are as they were
    assert "model.link_masses" not in model_values(first)  # a URDF arm's cones are unused
    text = (moved / "exo_arm.urdf").read_text()
    (moved / "exo_arm.urdf").write_text(text.replace('<mass value="1.4"/>',
                                                     '<mass value="1.5"/>'))
    changed = load_config(moved / "arm.yaml")
    assert changed.digest() != first.digest()
    assert learning_key(changed, reference) != learning_key(first, reference)
    assert model_values(changed) != model_values(first)


def test_one_value_for_every_joint() -> None:
    config = load_config(overrides={"control.kp": 12.0, "patient.friction.viscous": 0.5})
    assert config["control.kp"] == [12.0] * 3
    assert config["patient.friction.viscous"] == [0.5] * 3
    with pytest.raises(ConfigError) as info:
        config.replace({"control.kd": [1.0, -1.0, 2.0]})
    assert "control.kd: joint 'shoulder_abduction': must be >= 0, got -1.0" in str(info.value)
    with pytest.raises(ConfigError) as info:
        config.replace({"control.kd": [1.0, 2.0]})
    assert "one entry per joint (3: shoulder_flexion" in str(info.value)
    assert "one value for every joint or a map by joint name" in str(info.value)
    panda = load_config(ARMS / "panda.yaml")
    assert panda.joints == 7 and panda["control.kp"] == [16.0] * 7
    assert panda["safety.error_envelope"] == [1.0] * 7  # the shipped scalar, broadcast
    # a patient's per-joint key: once per joint of the patient (panda.yaml maps three)
    assert panda["patient.friction.viscous"] == [0.0] * 3
    assert panda["control.effort_limit"] == [87.0] * 4 + [12.0] * 3  # the URDF's <limit effort>
    with pytest.raises(ConfigError) as info:
        panda.replace({"control.kd": [8.0] * 6 + [-1.0]})
    assert "joint 'panda_joint7'" in str(info.value)


def test_locked_joints_and_joint_names_rules() -> None:
    panda = load_config(ARMS / "panda.yaml")
    with pytest.raises(ConfigError) as info:
        panda.replace({"model.locked_joints": "panda_finger_joint1 0.02"})
    assert "model.locked_joints" in str(info.value) and "'panda_finger_joint1 0.02'" in str(
        info.value)
    with pytest.raises(ConfigError) as info:  # found when the config is made, with the key
        panda.replace({"model.locked_joints": "panda_finger_joint1: 0.02"})
    assert info.value.key == "model.tip_link"
    assert "panda_finger_joint2" in str(info.value) and "lock it" in str(info.value)
    with pytest.raises(ConfigError) as info:
        panda.replace({"joint_names": [f"j{i}" for i in range(7)]})
    assert "joint_names: must be the moving joints" in str(info.value)
    assert "panda_joint1" in str(info.value)


@pytest.mark.parametrize("arm", ["panda", "ur5"])
def test_shipped_arm_learns_within_10_trials_at_10_percent(arm: str) -> None:
    """The linear law (with robust.yaml's Q-filter) over computed torque, plant masses +10 %:
    every joint within 0.005 rad by trial 10 and still there at the last (measured: 3 trials on
    both)."""
    config = load_config(ARMS / f"{arm}.yaml")
    result = run_trials(config, 0.10, 12)
    reached = result.iterations_to_bound()
    assert all(f is not None and f <= 10 for f in reached.first), reached
    assert np.all(result.max_abs_errors[-1] <= config["error_bound"])


def test_mujoco_plant_of_a_urdf_arm_equals_our_dynamics(tmp_path: Path) -> None:
    """MuJoCo's model of the arm (core/sim/mujoco_arm.py, from the kernels' arrays) of the
    Panda: mass matrix and bias forces equal ours (measured: 1.4e-15); `exo-ilc urdf` gives the
    chain the package uses (the fingers fixed at their locked values), whose arrays are the
    model's."""
    config = load_config(ARMS / "panda.yaml")
    plant = MujocoArm.from_config(config.with_mass_uncertainty(0.0))
    arm = build_arm(config)
    rng = np.random.default_rng(3)
    for _ in range(20):
        q, v = rng.uniform(-2.0, 2.0, 7), rng.uniform(-2.0, 2.0, 7)
        mass, bias = plant.inertia_and_bias(q, v)
        a, c = inertia_and_bias(q, v, *arm.kernel_args)
        np.testing.assert_allclose(mass, a, rtol=0, atol=1e-9 * np.abs(a).max())
        np.testing.assert_allclose(bias, c, rtol=0, atol=1e-9 * np.abs(c).max())
    out = tmp_path / "panda.urdf"
    assert cli_main(["urdf", "--config", str(ARMS / "panda.yaml"), "--out", str(out)]) == 0
    assert "prismatic" not in out.read_text()
    back = read_urdf_chain(out, "panda_link0", "panda_hand")
    for ours, read in zip(arm.kernel_args, back.kernel_args, strict=True):
        np.testing.assert_allclose(read, ours, rtol=0, atol=1e-12)


ONE_KHZ = {"law": "norm_optimal", "control.period": 0.001, "integration_step": 0.001,
           "safety.watchdog_periods": 100, "clock_every": 100}
"""What config/arms/panda_1khz_norm_optimal.yaml changes of panda.yaml (its "1 kHz" keys)."""


def test_panda_1khz_is_panda_but_its_1khz_keys() -> None:
    """The shipped 1 kHz norm-optimal Panda is panda.yaml with ONE_KHZ: the copy cannot drift."""
    fast = load_config(ARMS / "panda_1khz_norm_optimal.yaml")
    panda = load_config(ARMS / "panda.yaml")
    assert fast.values == panda.replace(ONE_KHZ).values
    assert panda.values != fast.values and build_reference(fast).samples == 5001


def test_panda_1khz_norm_optimal_within_the_bound_by_trial_3_at_10_percent() -> None:
    """Issue 27: the 1 kHz norm-optimal Panda has every joint within 0.005 rad at trial 3 at
    +10 % mass (measured: 2.6e-1, 1.3e-2, 4.2e-4 rad over trials 1-3; bench.norm_optimal_bench
    --arm times it)."""
    config = load_config(ARMS / "panda_1khz_norm_optimal.yaml")
    result = run_trials(config, 0.10, 3)
    worst = result.max_abs_errors.max(axis=1)
    assert worst[1] > config["error_bound"] >= worst[2], worst


def _panda_with_joint_dynamics(tmp_path: Path, apply: str) -> Any:
    """The shipped Panda config over a copy of its URDF whose arm joints have damping 0.8
    N m s/rad and friction 0.6 N m (the shipped file: 0.003 and 0), with
    model.urdf_joint_dynamics ``apply`` or ``ignore``."""
    text = (ROOT / "urdf" / "panda.urdf").read_text()
    assert text.count('damping="0.003" friction="0.0"') == 7
    (tmp_path / "panda.urdf").write_text(
        text.replace('damping="0.003" friction="0.0"', 'damping="0.8" friction="0.6"'))
    overlay = tmp_path / "dynamics.yaml"
    overlay.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"model": {
        "urdf": "panda.urdf", "urdf_joint_dynamics": apply}}}}))
    return load_config(ARMS / "panda.yaml", {"mass_uncertainty": 0.0}, [overlay])


@pytest.mark.parametrize("plant", ["urdf", "mjcf"])
def test_urdf_joint_dynamics_applied_equal_in_our_plant_and_mujoco(tmp_path: Path,
                                                                   plant: str) -> None:
    """model.urdf_joint_dynamics: apply: our plant's period (core/loop/stepper.py, the graph's
    and the trial's kernels; within a trial and between trials) with the URDF's -b qdot
    - F tanh(qdot / v_s) equals MuJoCo's,
    from the URDF by MuJoCo's parser (damping native, friction explicit: core/arm/
    mujoco_urdf.py) and from our arrays (core/sim/mujoco_arm.py); ignore: they differ by the
    joint forces. The nominal model (the controller's) never has them."""
    config = _panda_with_joint_dynamics(tmp_path, "apply")
    ignored = _panda_with_joint_dynamics(tmp_path, "ignore")
    chain = urdf_chain(config)
    assert urdf_joint_dynamics(config)[0] == pytest.approx([0.8] * 7)
    assert urdf_joint_dynamics(config)[1] == pytest.approx([0.6] * 7)
    ignored_forces = np.delete(PatientModel(ignored).joint, REST, axis=0)  # rest pose: no force
    assert not np.any(urdf_joint_dynamics(ignored)[0]) and not np.any(ignored_forces) \
        and not PatientModel(ignored).enabled
    assert config.digest() != ignored.digest()
    assert "model.urdf_joint_dynamics" not in ignored.identity_values()  # keys as before
    if plant == "urdf":
        mujoco_arm: Any = MujocoUrdfArm(
            tmp_path / "panda.urdf", "panda_link0", "panda_hand", dict(chain.locked),
            config["integration_step"], config["control.period"], damping=True,
            friction=True, friction_velocity=config["patient.friction.stribeck_velocity"])
    else:
        mujoco_arm = MujocoArm.from_config(config.with_mass_uncertainty(0.0))
    ours = PlantStepper(Experiment(config))
    rigid = PlantStepper(Experiment(ignored))
    rng = np.random.default_rng(11)
    worst = largest = 0.0
    for i in range(6):
        q, v = rng.uniform(-1.0, 1.0, 7), rng.uniform(-0.5, 0.5, 7)
        effort = rng.uniform(-5.0, 5.0, 7)
        results = []
        for stepper in (ours, rigid):
            if i % 2:
                stepper.begin_trial(1)  # within a trial: the patient's kernel
            else:
                stepper.reset()  # between trials (homing): the arm's forces alone
            stepper.position[:], stepper.velocity[:] = q, v
            assert stepper.step(effort) == 0
            results.append((stepper.position.copy(), stepper.velocity.copy()))
        mujoco_arm.set_state(q, v)
        if plant == "urdf":
            mq, mv = mujoco_arm.step(effort)
        else:
            assert mujoco_arm.step(effort) == 0
            mq, mv = mujoco_arm.position, mujoco_arm.velocity
        (oq, ov), (_, rv) = results
        worst = max(worst, np.abs(mq - oq).max(), np.abs(mv - ov).max())
        largest = max(largest, np.abs(mv - rv).max())
    assert worst < 1e-12, worst  # measured: 8e-15 (MjSpec), 6e-15 (MJCF) rad/s
    assert largest > 1e-3, largest  # ignore differs (measured: 4.8 rad/s)
    assert build_arm(config).kernel_args[0] == pytest.approx(build_arm(ignored).kernel_args[0])
    assert mujoco.get_mjcb_passive() is None  # the explicit friction's callback is scoped


def test_urdf_joint_dynamics_only_for_a_urdf_arm() -> None:
    with pytest.raises(ConfigError, match=r"model\.urdf_joint_dynamics"):
        load_config(overrides={"model.urdf_joint_dynamics": "apply"})
    with pytest.raises(ConfigError, match=r"model\.urdf_joint_dynamics"):
        load_config(overrides={"model.urdf_joint_dynamics": "on"})
    assert load_config().digest() == load_config(
        overrides={"model.urdf_joint_dynamics": "ignore"}).digest()


# --- a wrong URDF or reference through `exo-ilc simulate`: one line, exit code 2 -------------

def _two_joint_arm(tmp_path: Path, text: str = TWO_JOINTS, **model: Any) -> Path:
    urdf = tmp_path / "two.urdf"
    urdf.write_text(text)
    fields = {"source": "urdf", "urdf": "two.urdf", "base_link": "base", "tip_link": "tool",
              "locked_joints": "finger_joint: 0.3", **model}
    goal = model.pop("goal", [0.5, 0.5])
    return _arm_yaml(tmp_path / "two.yaml", {k: v for k, v in fields.items() if k != "goal"},
                     {"trajectory": {"start": 0.0, "goal": goal}})


def _simulate_error(config: Path, capsys: pytest.CaptureFixture[str]) -> str:
    code = cli_main(["simulate", "--config", str(config), "--trials", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_hand_written_arm_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = cli_main(["simulate", "--config", str(_two_joint_arm(tmp_path)), "--trials", "3",
                     "--quiet"])
    out = capsys.readouterr().out
    assert code == 0 and "shoulder" in out and "elbow" in out


def test_wrong_urdf_is_one_clear_error(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    line = _simulate_error(_two_joint_arm(tmp_path, urdf="nowhere.urdf"), capsys)
    assert "model.urdf" in line and "nowhere.urdf: no such URDF file" in line
    line = _simulate_error(_two_joint_arm(tmp_path, TWO_JOINTS.replace("</robot>", "")), capsys)
    assert "two.urdf: not well-formed XML" in line and "line" in line
    prismatic = TWO_JOINTS.replace('<joint name="elbow" type="revolute">',
                                   '<joint name="elbow" type="prismatic">')
    line = _simulate_error(_two_joint_arm(tmp_path, prismatic), capsys)
    assert "joint 'elbow'" in line and "prismatic" in line
    line = _simulate_error(_two_joint_arm(tmp_path, base_link="upper", tip_link="antenna"),
                           capsys)
    assert "tip link 'antenna' is not in the chain below base link 'upper'" in line
    line = _simulate_error(_two_joint_arm(tmp_path, MASSLESS_FOREARM), capsys)
    assert "singular at joint 'elbow'" in line
    line = _simulate_error(_two_joint_arm(tmp_path, goal=[0.5, 3.0]), capsys)
    assert "joint 'elbow' at t = " in line and "above its upper limit 2.5 rad" in line
    assert "<limit upper>" in line


def test_panda_reference_beyond_a_limit(capsys: pytest.CaptureFixture[str]) -> None:
    """The shipped start 0 on every joint is outside the Panda's joint 4 ([-3.07, -0.07])."""
    panda = load_config(ARMS / "panda.yaml", {"trajectory.start": 0.0})
    with pytest.raises(Exception, match=r"joint 'panda_joint4' at t = 0 s: q = 0 rad is above "
                                        r"its upper limit -0.0698 rad"):
        build_reference(panda)


def test_ros2_control_for_the_config_arm(tmp_path: Path) -> None:
    """`exo-ilc ros2-control`: the shipped controllers.yaml is its output for the shipped config;
    for the Panda it lists the URDF's seven joints in chain order."""
    out = tmp_path / "controllers.yaml"
    assert cli_main(["ros2-control", "--out", str(out)]) == 0
    assert out.read_text() == (ROOT / "config" / "ros2_control" / "controllers.yaml").read_text()
    assert cli_main(["ros2-control", "--config", str(ARMS / "panda.yaml"), "--out",
                     str(out)]) == 0
    document = yaml.safe_load(out.read_text())
    joints = [f"panda_joint{i}" for i in range(1, 8)]
    assert document["joint_state_broadcaster"]["ros__parameters"]["joints"] == joints
    assert document["effort_controller"]["ros__parameters"]["joints"] == joints
    assert document["controller_manager"]["ros__parameters"]["update_rate"] == 100


def test_urdf_arm_config_through_the_graphs_parameters_file(tmp_path: Path) -> None:
    """What `exo-ilc run` hands the nodes (to_ros_yaml, then each node's Config of its values)
    is the same URDF arm: same values, same digest."""
    panda = load_config(ARMS / "panda.yaml")
    out = tmp_path / "params.yaml"
    out.write_text(panda.to_ros_yaml("test"))
    again = load_config(out)
    assert again.values == panda.values and again.digest() == panda.digest()
    node = type(panda)(panda.values, "parameters of node test")
    assert node.digest() == panda.digest() and node.joints == 7


@pytest.mark.slow
@pytest.mark.parametrize("arm", ["panda", "ur5"])
def test_robust_settings_stay_bounded_for_300_trials(arm: str) -> None:
    """config/robust.yaml over the arm file (whose learning settings it already holds), plant
    masses +15 %, 300 trials (~10 s): within the
    bound from trial 10 on, the learned input settled and not growing (measured: max error
    6.4e-5 rad on the Panda, 2.2e-5 on the UR5; u_ff constant to 1e-13 of its size)."""
    config = load_config(ARMS / f"{arm}.yaml", overlays=[ROOT / "config" / "robust.yaml"])
    result = run_trials(config, 0.15, 300)
    assert np.all(result.max_abs_errors[10:] <= config["error_bound"])
    uff = result.max_abs_feedforward
    last = uff[150:]
    assert np.all(last.max(axis=0) - last.min(axis=0) <= 1e-6 * last.max(axis=0))
    fit = fit_growth(uff, window=150)
    assert fit is not None and not fit.any_growing
    assert np.all(uff < 0.5 * np.asarray(config["feedforward_limit"]))


def test_convergence_figure_has_one_panel_per_joint_of_any_arm() -> None:
    """Seven joints: seven panels, no paper's iterations in their titles (the paper's arm has
    three joints)."""
    config = load_config(ARMS / "panda.yaml")
    result = run_trials(config, 0.1, 3)
    figure = convergence_figure([RunSummary.from_result(result)], config["joint_names"])
    titles = [ax.get_title() for ax in figure.axes]
    assert len(titles) == 7 and all("paper" not in t for t in titles)
    assert titles[3].startswith("Joint 4 (panda_joint4)")


def test_tables_name_the_arms_joints_and_quote_the_paper_for_its_arm_only() -> None:
    """The iterations table and the comparison's footnote: a column per joint by the arm's
    joint names, the paper's joint-1 iterations only for the paper's arm (its joints), not
    for the Panda's seven."""
    from exo_ilc_ros.analysis.comparison import ComparedRun, format_comparison
    from exo_ilc_ros.analysis.report import format_iterations

    for config, paper in ((load_config(ARMS / "panda.yaml"), False), (load_config(), True)):
        names = config["joint_names"]
        summary = RunSummary.from_result(run_trials(config, 0.1, 2))
        table = format_iterations([summary], names)
        header = table.splitlines()[1]
        assert all(name in header for name in names)
        assert ("paper joint 1" in header) is paper and ("35/96/101" in table) is paper
        compared = format_comparison([ComparedRun("linear", summary)], names)
        assert ("paper, joint 1" in compared) is paper


def test_live_view_draws_the_urdf_arm() -> None:
    """The live view's arm (view_urdf): the cone arm's generated URDF as before; a URDF arm's own
    file, its root link and its locked joints at their values (the fingers' transforms move)."""
    cones = load_config()
    text, fixed, root = view_urdf(cones)
    assert text == arm_urdf(build_arm(cones), cones["joint_names"], cones["control.effort_limit"])
    assert fixed == {} and root == "base_link"
    panda = load_config(ARMS / "panda.yaml")
    text, fixed, root = view_urdf(panda)
    assert text == (ROOT / "urdf" / "panda.urdf").read_text() and root == "panda_link0"
    assert fixed == {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.02}
    kinematics = UrdfKinematics(text)
    q = dict(zip(panda["joint_names"], [0.1] * 7, strict=True))
    finger = {child: xyz for _, child, xyz, _ in kinematics.transforms({**fixed, **q})}
    closed = {child: xyz for _, child, xyz, _ in kinematics.transforms(q)}
    assert finger["panda_leftfinger"] != closed["panda_leftfinger"]
    assert set(kinematics.moving) >= set(panda["joint_names"])
    view = ArmView(panda)  # the live view's and the bag view's arm
    assert view.urdf == text and view.root_link == "panda_link0" and view.fixed_positions == fixed


def test_live_view_draws_the_persons_segments_on_their_links() -> None:
    """With a person strapped to the Panda, the view's URDF carries each segment as a cylinder
    on the link its ``person.<segment>.link`` names: its axis along the segment's direction from
    the proximal joint, its length the segment's, its radius sqrt(2 I_long / m); the arm's own
    links and joints are those of the file."""
    panda = load_config(ARMS / "panda.yaml", overlays=[ROOT / "config" / "person.yaml"])
    text, _, root = view_urdf(panda)
    assert root == "panda_link0"
    tree = ET.fromstring(text)
    plain = ET.fromstring((ROOT / "urdf" / "panda.urdf").read_text())
    assert [j.get("name") for j in tree.iter("joint")] == \
        [j.get("name") for j in plain.iter("joint")]
    segments, placements = person_segments(panda)
    assert set(placements) == {"upper_arm", "forearm", "hand"}
    for segment in segments:
        placement = placements[segment.name]
        link = next(link for link in tree.findall("link") if link.get("name") == placement.link)
        visual = next(v for v in link.findall("visual")
                      if v.get("name") == f"person_{segment.name}")
        cylinder = visual.find("geometry/cylinder")
        assert cylinder is not None
        assert float(cylinder.get("length", "0")) == pytest.approx(segment.length, rel=1e-5)
        radius = np.sqrt(2.0 * segment.inertia_longitudinal / segment.mass)
        assert float(cylinder.get("radius", "0")) == pytest.approx(radius, rel=1e-5)
        assert 0.02 < radius < 0.08  # an arm's thickness, not a link's or a torso's
        origin = visual.find("origin")
        assert origin is not None
        roll, pitch, yaw = (float(x) for x in origin.get("rpy", "").split())
        rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        ry = np.array([[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0],
                       [-np.sin(pitch), 0, np.cos(pitch)]])
        assert roll == 0.0
        direction = np.asarray(placement.direction) / np.linalg.norm(placement.direction)
        np.testing.assert_allclose(rz @ ry @ [0.0, 0.0, 1.0], direction, atol=1e-5)
        centre = np.array([float(x) for x in origin.get("xyz", "").split()])
        np.testing.assert_allclose(centre, np.asarray(placement.origin)
                                   + 0.5 * segment.length * direction, atol=1e-5)
    assert UrdfKinematics(text).moving  # the viewer's kinematics read it as before
    assert "person_" not in view_urdf(load_config(ARMS / "panda.yaml"))[0]  # no person, no segments
