"""A lab's URDF, second try (issue 36, point 4): gravity along any direction of the URDF's root
(a model drawn y up needs no wrapper URDF: the wrapper is the oracle, with Pinocchio and MuJoCo),
an empty base link is the root and an empty tip the single tip (or an error saying why not), a
tip that leaves a joint free beyond it is an error naming the arm file and the key,
`exo-ilc urdf` writes the chain the package uses, and the per-trial tables head their columns
with the arm's joint names."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from test_urdf_arm import _arm_yaml, _two_joint_arm
from test_urdf_chain import TWO_JOINTS, TWO_LOCKED, _pinocchio, _worst_relative

from exo_ilc_ros.analysis.report import format_trial_table
from exo_ilc_ros.cli.main import main as cli_main
from exo_ilc_ros.core import run_trials
from exo_ilc_ros.core.arm.build import build_arm, build_plant, urdf_chain
from exo_ilc_ros.core.arm.dynamics import inertia_and_bias
from exo_ilc_ros.core.arm.mujoco_urdf import MujocoUrdfArm
from exo_ilc_ros.core.arm.urdf_chain import read_urdf_chain
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.params.urdf_xml import UrdfKeyError
from exo_ilc_ros.core.session.summary import RunSummary

G = 9.81
Y_DOWN = [0.0, -G, 0.0]
"""Gravity of TWO_JOINTS read as a model drawn y up, in its root's frame."""
WRAPPED = TWO_JOINTS.replace(
    '<link name="world"/>',
    '<link name="ground"/>\n  <joint name="y_up" type="fixed">\n    <parent link="ground"/>'
    f'<child link="world"/>\n    <origin xyz="0 0 0" rpy="{math.pi / 2!r} 0 0"/>\n  </joint>\n'
    '  <link name="world"/>')
"""The hand-written wrapper a y-up model needed: a root whose z is the model's y (Rx(pi/2)
takes the model's y onto the wrapper's z), gravity along the wrapper's -z."""
URDF_DIR = config_dir().parent / "urdf"


def _states(dof: int, count: int = 20, seed: int = 11) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-np.pi, np.pi, dof), rng.uniform(-3.0, 3.0, dof))
            for _ in range(count)]


def test_gravity_along_the_roots_y_equals_the_wrapper_urdf() -> None:
    """TWO_JOINTS with gravity (0, -g, 0) in its root: the kernels' arrays of the wrapper URDF
    with the default gravity, to rounding (the wrapper's rotation is pi/2 in floating point)."""
    ours = read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED, Y_DOWN)
    wrapper = read_urdf_chain(WRAPPED, "base", "tool", TWO_LOCKED)
    for a, b in zip(ours.kernel_args, wrapper.kernel_args, strict=True):
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)
    default = read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED)
    assert np.linalg.norm(ours.gravity - default.gravity) > 1.0  # it does point elsewhere
    # a magnitude is along the root's -z, exactly as the vector (0, 0, -g)
    np.testing.assert_array_equal(
        read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED, [0.0, 0.0, -G]).gravity,
        default.gravity)


def test_gravity_along_the_roots_y_equals_pinocchio_and_mujoco() -> None:
    """Pinocchio's model of the same URDF with its gravity set to (0, -g, 0), and MuJoCo's
    (through the URDF's cut chain) given it: mass matrix, bias and forward dynamics equal
    ours."""
    chain = read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED, Y_DOWN)
    model, _ = _pinocchio(TWO_JOINTS, {**TWO_LOCKED, "antenna_joint": 0.0})
    model.gravity.linear = np.array(Y_DOWN)
    assert _worst_relative(chain.kernel_args, model, model.createData(), 2) < 1e-9
    mujoco_arm = MujocoUrdfArm(TWO_JOINTS, "base", "tool", TWO_LOCKED, gravity=Y_DOWN)
    np.testing.assert_allclose(mujoco_arm.model.opt.gravity, chain.gravity, atol=1e-15)
    for q, v in _states(2):
        a, c = inertia_and_bias(q, v, *chain.kernel_args)
        m, bias = mujoco_arm.inertia_and_bias(q, v)
        np.testing.assert_allclose(m, a, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(bias, c, rtol=1e-9, atol=1e-12)


def test_gravity_direction_key_reaches_the_model_the_plant_and_the_digest(
        tmp_path: Path) -> None:
    """``model.gravity_direction: [0, -1, 0]`` in an arm file: the nominal model and the plant
    take the wrapper's gravity; the key is in the digest only when it is not -z (a config
    that does not give it keeps its digest); a cone arm takes it too, in Oxyz."""
    y_up = load_config(_two_joint_arm(tmp_path, gravity_direction=[0.0, -2.0, 0.0]))
    wrapper = read_urdf_chain(WRAPPED, "base", "tool", TWO_LOCKED)
    np.testing.assert_allclose(build_arm(y_up).gravity, wrapper.gravity, atol=1e-12)
    np.testing.assert_allclose(build_plant(y_up).gravity, wrapper.gravity, atol=1e-12)
    plain = load_config(_two_joint_arm(tmp_path))
    assert "model.gravity_direction" not in plain.identity_values()
    assert "model.gravity_direction" in y_up.identity_values()
    assert y_up.digest() != plain.digest()
    down = load_config(_two_joint_arm(tmp_path, gravity_direction=[0.0, 0.0, -3.0]))
    assert down.digest() == plain.digest()
    np.testing.assert_array_equal(build_arm(down).gravity, build_arm(plain).gravity)
    cones = load_config(overrides={"model.gravity_direction": [1.0, 0.0, 0.0]})
    np.testing.assert_array_equal(build_arm(cones).gravity, [G, 0.0, 0.0])
    with pytest.raises(ConfigError, match=r"model\.gravity_direction"):
        load_config(overrides={"model.gravity_direction": [0.0, 0.0, 0.0]})


def test_empty_base_link_is_the_root_and_empty_tip_the_single_tip(tmp_path: Path) -> None:
    """``base_link: ""`` is the URDF's root, ``tip_link: ""`` its single tip: the UR5's chain
    from ``world`` to ``wrist_3_link`` (where only fixed tool frames branch off) is the shipped
    config's; TWO_JOINTS from its root ``world`` (the base's mount above it) has the same
    dynamics as from ``base``."""
    ends = tmp_path / "ends.yaml"
    ends.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        "model": {"base_link": "", "tip_link": ""}}}}))
    shipped = load_config(config_dir() / "arms" / "ur5.yaml")
    found = load_config(config_dir() / "arms" / "ur5.yaml", overlays=[ends])
    assert (found["model.base_link"], found["model.tip_link"]) == ("world", "wrist_3_link")
    assert found["joint_names"] == shipped["joint_names"]
    for a, b in zip(build_arm(found).kernel_args, build_arm(shipped).kernel_args, strict=True):
        np.testing.assert_array_equal(a, b)
    two = load_config(_two_joint_arm(tmp_path, base_link="", tip_link=""))
    assert (two["model.base_link"], two["model.tip_link"]) == ("world", "finger")
    assert two["joint_names"] == ["shoulder", "elbow"]
    assert urdf_chain(two).dropped_links == ("antenna",)
    from_base = read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED)
    for q, v in _states(2):
        a, c = inertia_and_bias(q, v, *build_arm(two).kernel_args)
        a0, c0 = inertia_and_bias(q, v, *from_base.kernel_args)
        np.testing.assert_allclose(a, a0, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(c, c0, rtol=1e-12, atol=1e-12)


TWO_ARMS = """<?xml version="1.0"?>
<robot name="two_arms">
  <link name="torso"><inertial><mass value="10"/>
    <inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
""" + "".join(f"""  <joint name="{side}_shoulder" type="revolute">
    <parent link="torso"/><child link="{side}_arm"/>
    <origin xyz="0 {y} 0.5" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="20" velocity="2"/>
  </joint>
  <link name="{side}_arm"><inertial><origin xyz="0 0 -0.15"/><mass value="1.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.002"/></inertial></link>
""" for side, y in (("left", 0.2), ("right", -0.2))) + "</robot>\n"


def _arm_file(tmp_path: Path, text: str, model: dict[str, Any]) -> Path:
    (tmp_path / "arm.urdf").write_text(text)
    return _arm_yaml(tmp_path / "arm.yaml", {"source": "urdf", "urdf": "arm.urdf", **model},
                     {"trajectory": {"start": 0.0, "goal": 0.5}})


def test_an_empty_end_the_urdf_does_not_tell_is_a_clear_error(tmp_path: Path) -> None:
    """Two arms on a torso: no single tip (the error names the branches and the key); a URDF
    with nothing that moves below the base; two roots."""
    with pytest.raises(ConfigError) as error:
        load_config(_arm_file(tmp_path, TWO_ARMS, {"base_link": "", "tip_link": ""}))
    assert error.value.key == "model.tip_link" and error.value.source == str(tmp_path /
                                                                              "arm.yaml")
    assert "branches below link 'torso' into 2 chains" in str(error.value)
    assert "'left_arm', 'right_arm'" in str(error.value) and "name the tip link" in str(
        error.value)
    chosen = load_config(_arm_file(tmp_path, TWO_ARMS, {"base_link": "",
                                                        "tip_link": "right_arm"}))
    assert chosen["joint_names"] == ["right_shoulder"]
    with pytest.raises(UrdfKeyError, match="no revolute or continuous joint"):
        read_urdf_chain(TWO_ARMS, "left_arm", "")
    two_roots = TWO_ARMS.replace("</robot>", '<link name="stray"/></robot>')
    with pytest.raises(UrdfKeyError, match=r"2 root links \('torso', 'stray'\)") as root:
        read_urdf_chain(two_roots, "", "left_arm")
    assert root.value.key == "model.base_link"


def test_a_tip_with_a_free_joint_beyond_it_names_the_arm_file_and_the_key(
        tmp_path: Path) -> None:
    """The Panda to its hand with the fingers not locked: the config error names the arm file,
    ``model.tip_link``, the URDF and the finger joint, when the config is loaded (not when the
    arm is first built); a free joint on a branch off a moving link names
    ``model.locked_joints``."""
    arm = tmp_path / "panda_hand.yaml"
    arm.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"model": {
        "source": "urdf", "urdf": str(URDF_DIR / "panda.urdf"), "base_link": "panda_link0",
        "tip_link": "panda_hand"}}}}))
    with pytest.raises(ConfigError) as error:
        load_config(arm)
    message = str(error.value)
    assert error.value.key == "model.tip_link" and error.value.source == str(arm)
    assert message.startswith(f"{arm}: model.tip_link: {URDF_DIR / 'panda.urdf'}: joint "
                              "'panda_finger_joint1' (prismatic) moves link 'panda_leftfinger' "
                              "beyond the tip link 'panda_hand'")
    branch = TWO_JOINTS.replace('<parent link="base"/><child link="antenna"/>',
                                '<parent link="upper"/><child link="antenna"/>')
    with pytest.raises(ConfigError) as error:
        load_config(_two_joint_arm(tmp_path, branch))
    assert error.value.key == "model.locked_joints"
    assert "joint 'antenna_joint' (revolute) moves link 'antenna' off the chain 'base' -> " \
        "'tool' (it hangs from link 'upper', which moves)" in str(error.value)


def test_urdf_command_writes_the_chain_the_package_uses(tmp_path: Path) -> None:
    """`exo-ilc urdf --config` of a URDF arm: the links above the base, the dropped branch and
    the locks are gone (locked joints fixed at their values), and the file read back as it is
    (no locks, gravity as its comment says) gives the config's chain; shapes kept."""
    config_file = _two_joint_arm(tmp_path, gravity_direction=[0.0, -1.0, 0.0])
    out = tmp_path / "chain.urdf"
    assert cli_main(["urdf", "--config", str(config_file), "--out", str(out)]) == 0
    text = out.read_text()
    assert text != TWO_JOINTS
    for gone in ('name="world"', 'name="antenna"', 'name="mount"', 'name="antenna_joint"'):
        assert gone not in text
    assert '<joint name="finger_joint" type="fixed">' in text
    config = load_config(config_file)
    used = urdf_chain(config)
    comment = text.split("<!--", 1)[1].split("-->", 1)[0]
    assert "locked joints made fixed (finger_joint: 0.3)" in comment
    assert "links dropped (antenna)" in comment
    direction = [float(x) for x in comment.split("model.gravity_direction [")[1]
                 .split("]")[0].split(",")]
    back = read_urdf_chain(out, "base", "tool", {},
                           G * np.array(direction) / np.linalg.norm(direction))
    assert back.joint_names == used.joint_names
    for a, b in zip(back.kernel_args, used.kernel_args, strict=True):
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-5)  # the comment's 6 digits
    for a, b in zip(back.kernel_args[:-1], used.kernel_args[:-1], strict=True):
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)
    panda = tmp_path / "panda.urdf"
    assert cli_main(["urdf", "--config", str(config_dir() / "arms" / "panda.yaml"), "--out",
                     str(panda)]) == 0
    written = panda.read_text()
    assert "prismatic" not in written and written.count("<visual") == \
        (URDF_DIR / "panda.urdf").read_text().count("<visual")
    shipped = urdf_chain(load_config(config_dir() / "arms" / "panda.yaml"))
    for a, b in zip(read_urdf_chain(panda, "panda_link0", "panda_hand").kernel_args,
                    shipped.kernel_args, strict=True):
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)


def test_trial_tables_head_their_columns_with_the_joint_names(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The per-trial tables of simulate (and of run and analyze: the same function) name each
    column by its joint, each as wide as its name."""
    config = load_config(overrides={"trajectory.duration": 0.5})
    summary = RunSummary.from_result(run_trials(config, 0.05, trials=2))
    names = config["joint_names"]
    for quantity in ("error", "feedforward", "effort"):
        lines = format_trial_table([summary], names, quantity).splitlines()
        assert lines[2].split() == ["|", *names]
        row = lines[4]
        assert row.startswith("    1 |") and len(row.split()) == 2 + len(names)
        at = row.index("|")
        for name, cell in zip(names, row.split()[2:], strict=True):  # right-aligned under it
            at = row.index(cell, at)
            assert lines[2].index(name) + len(name) == at + len(cell.rstrip("*"))
            at += len(cell)
    arm = tmp_path / "short.yaml"
    arm.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        "trajectory": {"duration": 0.5}}}}))
    assert cli_main(["simulate", "--config", str(arm), "--trials", "1"]) == 0
    out = capsys.readouterr().out
    assert "shoulder_flexion shoulder_abduction elbow_flexion" in out.split("(* above")[0]
    assert " e1 " not in out
