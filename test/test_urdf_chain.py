"""The URDF reader (core/arm/urdf_chain.py): its arrays give Pinocchio's mass matrix, bias forces
and forward dynamics (UR5, Panda with fingers locked, a hand-written 2-joint arm with rotated
frames, a continuous joint, merged fixed links, a dropped branch and a locked joint); the
paper's arm through `exo-ilc urdf` gives the ArmModel's dynamics; every error names the element."""

from __future__ import annotations

from pathlib import Path

import example_robot_data
import numpy as np
import pinocchio as pin
import pytest

from exo_ilc_ros.cli.main import main as cli_main
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.arm.dynamics import inertia_and_bias, solve_spd
from exo_ilc_ros.core.arm.urdf_chain import LimitError, check_reference_limits, read_urdf_chain
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.core.params.urdf_xml import UrdfError, resolve_package_uri

TWO_JOINTS = """<?xml version="1.0"?>
<robot name="two">
  <link name="world"/>
  <joint name="mount" type="fixed">
    <parent link="world"/><child link="base"/>
    <origin xyz="0.1 -0.2 0.5" rpy="0.3 -0.2 0.1"/>
  </joint>
  <link name="base">
    <inertial><mass value="5.0"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>
    </inertial>
  </link>
  <joint name="antenna_joint" type="revolute">
    <parent link="base"/><child link="antenna"/>
    <origin xyz="0 0.1 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="antenna">
    <inertial><mass value="0.3"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="shoulder" type="continuous">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0.02 0.03 0.1" rpy="0.4 0.1 -0.7"/><axis xyz="0 0.6 0.8"/>
    <limit effort="30" velocity="3"/>
    <dynamics damping="0.5" friction="0.2"/>
  </joint>
  <link name="upper">
    <inertial>
      <origin xyz="0.01 -0.02 0.15" rpy="0.2 0.5 -0.3"/><mass value="1.7"/>
      <inertia ixx="0.02" ixy="0.001" ixz="-0.002" iyy="0.018" iyz="0.0015" izz="0.006"/>
    </inertial>
  </link>
  <joint name="upper_cover_joint" type="fixed">
    <parent link="upper"/><child link="upper_cover"/>
    <origin xyz="0.0 0.05 0.2" rpy="0 0.3 0"/>
  </joint>
  <link name="upper_cover">
    <inertial>
      <origin xyz="0.01 0 0" rpy="0 0 0.4"/><mass value="0.4"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.003"/>
    </inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0 0 0.3" rpy="-0.5 0.2 0.3"/><axis xyz="1 0 0"/>
    <limit lower="-2.0" upper="2.5" effort="12" velocity="4"/>
  </joint>
  <link name="fore">
    <inertial>
      <origin xyz="0 0.01 0.12" rpy="0 0 0"/><mass value="1.1"/>
      <inertia ixx="0.01" ixy="0" ixz="0.0005" iyy="0.011" iyz="0" izz="0.002"/>
    </inertial>
  </link>
  <joint name="tool_joint" type="fixed">
    <parent link="fore"/><child link="tool"/><origin xyz="0 0 0.25" rpy="0.1 0 0"/>
  </joint>
  <link name="tool"/>
  <joint name="finger_joint" type="revolute">
    <parent link="tool"/><child link="finger"/>
    <origin xyz="0 0.02 0.03" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="finger">
    <inertial><origin xyz="0 0 0.02" rpy="0 0 0"/><mass value="0.2"/>
      <inertia ixx="0.0002" ixy="0" ixz="0" iyy="0.0002" iyz="0" izz="0.0001"/></inertial>
  </link>
</robot>
"""
MASSLESS_FOREARM = TWO_JOINTS.replace('<mass value="1.1"/>', '<mass value="0.0"/>').replace(
    'ixx="0.01" ixy="0" ixz="0.0005" iyy="0.011" iyz="0" izz="0.002"',
    'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"').replace(
    '<mass value="0.2"/>', '<mass value="0.0"/>').replace(
    'ixx="0.0002" ixy="0" ixz="0" iyy="0.0002" iyz="0" izz="0.0001"',
    'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"')
"""TWO_JOINTS with nothing of mass beyond the elbow: a singular mass matrix at the elbow."""
TWO_LOCKED = {"finger_joint": 0.3}


def _pinocchio(text: str, locked: dict[str, float]) -> tuple[pin.Model, pin.Data]:
    """Pinocchio's model of the URDF, ``locked`` joints held (buildReducedModel)."""
    model = pin.buildModelFromXML(text)
    if locked:
        q = pin.neutral(model)
        ids = []
        for name, value in locked.items():
            joint = model.getJointId(name)
            ids.append(joint)
            q[model.joints[joint].idx_q] = value
        model = pin.buildReducedModel(model, ids, q)
    return model, model.createData()


def _pin_q(model: pin.Model, q: np.ndarray) -> np.ndarray:
    """Pinocchio's configuration of joint angles q (a continuous joint is (cos, sin))."""
    out = pin.neutral(model)
    for j, angle in enumerate(q):
        joint = model.joints[j + 1]
        if joint.nq == 2:
            out[joint.idx_q:joint.idx_q + 2] = (np.cos(angle), np.sin(angle))
        else:
            out[joint.idx_q] = angle
    return out


def _worst_relative(chain_args: tuple[np.ndarray, ...], model: pin.Model, data: pin.Data,
                    dof: int, seed: int = 3, count: int = 50) -> float:
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(count):
        q = rng.uniform(-np.pi, np.pi, dof)
        v = rng.uniform(-3.0, 3.0, dof)
        tau = rng.uniform(-20.0, 20.0, dof)
        a, c = inertia_and_bias(q, v, *chain_args)
        qp = _pin_q(model, q)
        m = pin.crba(model, data, qp)
        m = np.triu(m) + np.triu(m, 1).T
        bias = pin.rnea(model, data, qp, v, np.zeros(dof))
        qdd = pin.aba(model, data, qp, v, tau)
        ours = solve_spd(a, tau - c)
        worst = max(worst, np.max(np.abs(a - m)) / np.max(np.abs(m)),
                    np.max(np.abs(c - bias)) / np.max(np.abs(bias)),
                    np.max(np.abs(ours - qdd)) / np.max(np.abs(qdd)))
    return worst


ROBOTS = [("ur5", "base_link", "tool0", {}, 6),
          ("panda", "panda_link0", "panda_hand",
           {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.035}, 7),
          ("kinova", "base", "j2s6s200_end_effector", {}, 6),  # 3 continuous joints
          ("xarm7", "world", "link_eef", {}, 7)]  # <dynamics damping friction>


@pytest.mark.parametrize(("robot", "base", "tip", "locked", "dof"), ROBOTS,
                         ids=[r[0] for r in ROBOTS])
def test_public_arms_equal_pinocchio(robot: str, base: str, tip: str,
                                     locked: dict[str, float], dof: int) -> None:
    path = example_robot_data.load(robot).urdf
    chain = read_urdf_chain(path, base, tip, locked)
    assert chain.dof == dof
    model, data = _pinocchio(Path(path).read_text(), locked)
    assert model.nv == dof
    assert _worst_relative(chain.kernel_args, model, data, dof) < 1e-9
    assert chain.joint_names == tuple(model.names[1:])
    np.testing.assert_allclose(chain.effort_limit, model.effortLimit)
    np.testing.assert_allclose(chain.velocity_limit, model.velocityLimit)
    if model.nq == model.nv:  # no continuous joint (Pinocchio's are (cos, sin))
        np.testing.assert_allclose(chain.position_lower, model.lowerPositionLimit)
        np.testing.assert_allclose(chain.position_upper, model.upperPositionLimit)
    else:
        assert sum(chain.continuous) == model.nq - model.nv
        assert np.all(np.isinf(chain.position_lower[list(chain.continuous)]))
    text = Path(path).read_text()
    if 'damping="10"' in text:  # xArm7: damping 10/10/5/5/5/2/2, friction 1 N m
        np.testing.assert_array_equal(chain.damping, [10, 10, 5, 5, 5, 2, 2])
        np.testing.assert_array_equal(chain.friction, [1.0] * 7)


def test_panda_fingers_are_merged_into_the_last_body() -> None:
    path = example_robot_data.load("panda").urdf
    chain = read_urdf_chain(path, "panda_link0", "panda_hand",
                            {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0})
    assert chain.merged_links[-1][0] == "panda_link7"
    assert {"panda_hand", "panda_leftfinger", "panda_rightfinger"} <= set(chain.merged_links[-1])
    assert chain.locked == (("panda_finger_joint1", 0.0), ("panda_finger_joint2", 0.0))


def test_hand_written_arm_equals_pinocchio() -> None:
    """Rotated joint and inertial frames, an oblique axis, a continuous joint, a fixed link
    merged, a moving branch on the base dropped (locked in Pinocchio: it cannot move the chain),
    a locked joint with mass beyond the tip, gravity rotated into the base frame."""
    chain = read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED)
    assert chain.joint_names == ("shoulder", "elbow")
    assert chain.continuous == (True, False)
    assert chain.dropped_links == ("antenna",)
    assert chain.merged_links == (("upper", "upper_cover"), ("fore", "tool", "finger"))
    np.testing.assert_array_equal(chain.position_lower, [-np.inf, -2.0])
    np.testing.assert_array_equal(chain.position_upper, [np.inf, 2.5])
    np.testing.assert_array_equal(chain.effort_limit, [30.0, 12.0])
    np.testing.assert_array_equal(chain.velocity_limit, [3.0, 4.0])
    np.testing.assert_array_equal(chain.damping, [0.5, 0.0])
    np.testing.assert_array_equal(chain.friction, [0.2, 0.0])
    assert chain.source == "<text>"
    model, data = _pinocchio(TWO_JOINTS, {**TWO_LOCKED, "antenna_joint": 0.0})
    assert model.nv == 2
    assert _worst_relative(chain.kernel_args, model, data, 2) < 1e-9
    # the root's gravity, rotated into the base link's frame
    assert abs(chain.gravity[2]) < 9.81 and np.linalg.norm(chain.gravity) == pytest.approx(9.81)


def test_digest_is_of_the_contents_not_the_path(tmp_path: Path) -> None:
    first, second = tmp_path / "a.urdf", tmp_path / "b" / "c.urdf"
    second.parent.mkdir()
    first.write_text(TWO_JOINTS)
    second.write_text(TWO_JOINTS)
    a = read_urdf_chain(first, "base", "tool", TWO_LOCKED)
    b = read_urdf_chain(str(second), "base", "tool", TWO_LOCKED)
    assert a.digest == b.digest == read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED).digest
    assert a.source == str(first)
    changed = read_urdf_chain(TWO_JOINTS.replace('value="1.1"', 'value="1.2"'), "base", "tool",
                              TWO_LOCKED)
    assert changed.digest != a.digest


def test_paper_arm_through_its_urdf(tmp_path: Path) -> None:
    """`exo-ilc urdf` output read back gives the ArmModel's kernels' arrays bit for bit (so the
    same trials) and its dynamics to 1e-12 (the file is well-formed XML: its comment holds no
    double hyphen)."""
    out = tmp_path / "exo_arm.urdf"
    assert cli_main(["urdf", "--out", str(out)]) == 0
    config = load_config()
    arm = build_arm(config)
    chain = read_urdf_chain(out, "base_link", "forearm_link")
    assert chain.joint_names == tuple(config["joint_names"])
    np.testing.assert_array_equal(chain.effort_limit, config["control.effort_limit"])
    for ours, theirs in zip(chain.kernel_args, arm.kernel_args, strict=True):
        np.testing.assert_array_equal(ours, theirs)  # bit for bit: the same trials
    rng = np.random.default_rng(11)
    for _ in range(50):
        q, v = rng.uniform(-np.pi, np.pi, 3), rng.uniform(-4.0, 4.0, 3)
        tau = rng.uniform(-10.0, 10.0, 3)
        a, c = inertia_and_bias(q, v, *chain.kernel_args)
        np.testing.assert_allclose(a, arm.metric_tensor(q), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(c, arm.bias_forces(q, v), rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(solve_spd(a, tau - c), arm.forward_dynamics(q, v, tau),
                                   rtol=1e-12, atol=1e-12)


# --- errors: one clear message naming the element ------------------------------------------

def _error(source: str | Path, base: str = "base", tip: str = "tool",
           locked: dict[str, float] | None = None) -> str:
    with pytest.raises(UrdfError) as info:
        read_urdf_chain(source, base, tip, TWO_LOCKED if locked is None else locked)
    return str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere.urdf"
    assert str(missing) in _error(missing) and "no such URDF file" in _error(missing)


def test_bad_xml(tmp_path: Path) -> None:
    bad = tmp_path / "bad.urdf"
    bad.write_text(TWO_JOINTS.replace("</robot>", ""))
    message = _error(bad)
    assert str(bad) in message and "not well-formed XML" in message and "line" in message
    comment = "<?xml version='1.0'?><!-- exo-ilc urdf --out x --><robot name='r'/>"
    assert "not well-formed XML" in _error(comment)


def test_prismatic_joint_on_the_chain() -> None:
    text = TWO_JOINTS.replace('<joint name="elbow" type="revolute">',
                              '<joint name="elbow" type="prismatic">')
    message = _error(text)
    assert "joint 'elbow'" in message and "prismatic" in message
    # locked, it is a fixed link of the chain
    assert read_urdf_chain(text, "base", "tool", {**TWO_LOCKED, "elbow": 0.1}).dof == 1


def test_floating_base() -> None:
    text = TWO_JOINTS.replace('<joint name="mount" type="fixed">',
                              '<joint name="mount" type="floating">')
    message = _error(text, base="world")
    assert "joint 'mount'" in message and "floating" in message
    assert read_urdf_chain(text, "base", "tool", TWO_LOCKED).dof == 2  # below it: fine


def test_branch_that_could_move() -> None:
    message = _error(TWO_JOINTS, locked={})
    assert "joint 'finger_joint'" in message and "beyond the tip link 'tool'" in message
    assert "lock it" in message


def test_tip_not_in_the_chain() -> None:
    assert "tip link 'nothing' is not a link" in _error(TWO_JOINTS, tip="nothing")
    assert "base link 'nothing' is not a link" in _error(TWO_JOINTS, base="nothing")
    message = _error(TWO_JOINTS, base="upper", tip="antenna")
    assert "tip link 'antenna' is not in the chain below base link 'upper'" in message
    assert "no revolute or continuous joint" in _error(TWO_JOINTS, base="fore", tip="tool")


def test_singular_mass_matrix() -> None:
    """A massless forearm (nothing beyond the elbow), and two collocated joints about the same
    axis with a massless link between them: the error names the joint."""
    message = _error(MASSLESS_FOREARM, locked={"finger_joint": 0.3})
    assert "singular at joint 'elbow'" in message
    twin = TWO_JOINTS.replace(
        '<origin xyz="0 0 0.3" rpy="-0.5 0.2 0.3"/><axis xyz="1 0 0"/>',
        '<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0.6 0.8"/>').replace(
        '<mass value="1.7"/>', '<mass value="0.0"/>').replace(
        'ixx="0.02" ixy="0.001" ixz="-0.002" iyy="0.018" iyz="0.0015" izz="0.006"',
        'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"').replace(
        '<mass value="0.4"/>', '<mass value="0.0"/>').replace(
        'ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.003"',
        'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"')
    assert "singular at joint 'elbow'" in _error(twin)


def test_other_malformed_elements() -> None:
    assert "link 'nowhere' is not defined" in _error(TWO_JOINTS.replace(
        '<parent link="fore"/><child link="tool"/>',
        '<parent link="nowhere"/><child link="tool"/>'))
    assert "joint 'elbow' <origin xyz>" in _error(TWO_JOINTS.replace(
        '<origin xyz="0 0 0.3" rpy="-0.5 0.2 0.3"/>', '<origin xyz="0 0.3" rpy="0 0 0"/>'))
    assert "locked joint 'nope' is not in the URDF" in _error(TWO_JOINTS, locked={"nope": 0.0})
    assert "root element is <robots>" in _error("<robots/>")


def test_package_uri(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """package:// through the ament index (a prefix laid out as colcon installs one); without
    the package, or without any ROS environment, a clear error."""
    prefix = tmp_path / "install"
    (prefix / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (prefix / "share" / "ament_index" / "resource_index" / "packages" / "my_arm").write_text("")
    (prefix / "share" / "my_arm" / "urdf").mkdir(parents=True)
    (prefix / "share" / "my_arm" / "urdf" / "two.urdf").write_text(TWO_JOINTS)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    uri = "package://my_arm/urdf/two.urdf"
    assert resolve_package_uri(uri) == prefix / "share" / "my_arm" / "urdf" / "two.urdf"
    assert read_urdf_chain(uri, "base", "tool", TWO_LOCKED).joint_names == ("shoulder", "elbow")
    with pytest.raises(UrdfError, match="package 'no_such_package_here' is not installed"):
        resolve_package_uri("package://no_such_package_here/urdf/arm.urdf")
    monkeypatch.delenv("AMENT_PREFIX_PATH")
    assert "AMENT_PREFIX_PATH is not set" in _error(uri)


def test_reference_beyond_a_joint_limit() -> None:
    """The earliest sample out of a URDF limit, named by joint, time and value (the elbow's
    position limits -2 / 2.5 rad and 4 rad/s; the continuous shoulder has none but 3 rad/s)."""
    chain = read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED)
    time = np.linspace(0.0, 2.0, 201)
    position = np.column_stack([10.0 * time, 1.2 * time])  # elbow above 2.5 from t = 2.09: never
    velocity = np.column_stack([np.full_like(time, 2.9), np.full_like(time, 1.2)])
    check_reference_limits(chain, time, position, velocity)  # within every limit
    position[150:, 1] = 2.6
    with pytest.raises(LimitError, match=r"joint 'elbow' at t = 1\.5 s: q = 2\.6 rad is above "
                                         r"its upper limit 2\.5 rad \(<text> <limit upper>\)"):
        check_reference_limits(chain, time, position, velocity)
    velocity[120:, 0] = -3.5  # earlier than the elbow's position
    with pytest.raises(LimitError, match=r"joint 'shoulder' at t = 1\.2 s: qdot = -3\.5 rad/s "
                                         r"is beyond its limit 3 rad/s"):
        check_reference_limits(chain, time, position, velocity, "exercise reach")
    position[10, 1] = -2.1
    with pytest.raises(LimitError, match=r"^the reference: joint 'elbow' at t = 0\.1 s: "
                                         r"q = -2\.1 rad is below its lower limit -2 rad"):
        check_reference_limits(chain, time, position, velocity)
    with pytest.raises(LimitError, match="3 joints, the URDF's chain has 2"):
        check_reference_limits(chain, time, np.zeros((201, 3)), np.zeros((201, 3)))
