"""MuJoCo from the same URDF (core/arm/mujoco_urdf.py, MuJoCo's own URDF parser through MjSpec):
its mass matrix and bias equal our kernels' on the chain read by core/arm/urdf_chain.py (UR5,
Panda with fingers locked, the hand-written 2-joint arm), its RK4 period equals our plant's, and
the joint effects are what the module says."""

from __future__ import annotations

import example_robot_data
import mujoco
import numpy as np
import pytest
from test_urdf_chain import TWO_JOINTS, TWO_LOCKED

from exo_ilc_ros.core.arm.dynamics import inertia_and_bias
from exo_ilc_ros.core.arm.mujoco_urdf import MujocoUrdfArm, chain_urdf
from exo_ilc_ros.core.arm.urdf_chain import read_urdf_chain
from exo_ilc_ros.core.loop.plant import PlantDynamics, integrate_period
from exo_ilc_ros.core.params.urdf_xml import UrdfError

ARMS = [("ur5", "base_link", "tool0", {}),
        ("panda", "panda_link0", "panda_hand",
         {"panda_finger_joint1": 0.02, "panda_finger_joint2": 0.035}),
        ("kinova", "base", "j2s6s200_end_effector", {}),  # .dae collision meshes
        ("xarm7", "world", "link_eef", {}),
        ("two", "base", "tool", TWO_LOCKED)]


def _arm(name: str, base: str, tip: str, locked: dict[str, float], **options: object
         ) -> MujocoUrdfArm:
    source = TWO_JOINTS if name == "two" else example_robot_data.load(name).urdf
    return MujocoUrdfArm(source, base, tip, locked, **options)  # type: ignore[arg-type]


@pytest.mark.parametrize(("name", "base", "tip", "locked"), ARMS, ids=[a[0] for a in ARMS])
def test_mass_matrix_and_bias_equal_ours(name: str, base: str, tip: str,
                                         locked: dict[str, float]) -> None:
    arm = _arm(name, base, tip, locked)
    chain = arm.chain
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(50):
        q, v = rng.uniform(-np.pi, np.pi, chain.dof), rng.uniform(-3.0, 3.0, chain.dof)
        a, c = inertia_and_bias(q, v, *chain.kernel_args)
        m, bias = arm.inertia_and_bias(q, v)
        worst = max(worst, np.max(np.abs(a - m)) / np.max(np.abs(m)),
                    np.max(np.abs(c - bias)) / np.max(np.abs(bias)))
    assert worst < 1e-9


@pytest.mark.parametrize(("name", "base", "tip", "locked"), [ARMS[1], ARMS[-1]],
                         ids=["panda", "two"])
def test_rk4_period_equals_our_plant(name: str, base: str, tip: str,
                                     locked: dict[str, float]) -> None:
    """One 10 ms control period, effort held, RK4 at 1 ms in both."""
    arm = _arm(name, base, tip, locked, timestep=0.001, period=0.01)
    chain = arm.chain
    rng = np.random.default_rng(6)
    for _ in range(5):
        q, v = rng.uniform(-1.0, 1.0, chain.dof), rng.uniform(-1.0, 1.0, chain.dof)
        effort = rng.uniform(-5.0, 5.0, chain.dof)
        arm.set_state(q, v)
        mq, mv = arm.step(effort)
        oq, ov = integrate_period(q, v, effort, 0.01, 10, chain.kernel_args, chain.kernel_args,
                                  int(PlantDynamics.FULL))
        np.testing.assert_allclose(mq, oq, rtol=0.0, atol=1e-10)
        np.testing.assert_allclose(mv, ov, rtol=0.0, atol=1e-9)


def test_model_options_and_joint_effects() -> None:
    """One motor per joint, RK4, contacts and joint limits off; the URDF's damping and friction
    not in MuJoCo's rigid body, damping=True puts -b qdot back as MuJoCo's passive torque,
    friction=True adds -F tanh(qdot / v_s) to it."""
    arm = _arm("two", "base", "tool", TWO_LOCKED, timestep=0.002, period=0.01)
    model = arm.model
    assert model.nu == 2 and model.njnt == 2
    assert [model.actuator(i).name for i in range(2)] == ["shoulder_motor", "elbow_motor"]
    assert list(model.actuator_trnid[:, 0]) == [0, 1]
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert model.opt.timestep == 0.002 and arm.substeps == 5
    assert model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    assert not np.any(model.jnt_limited)
    assert not np.any(model.dof_damping) and not np.any(model.dof_frictionloss)
    assert not np.any(model.dof_armature)
    assert arm.chain.damping[0] == 0.5 and arm.chain.friction[0] == 0.2
    arm.set_state([0.3, -0.2], [1.5, -2.0])
    np.testing.assert_array_equal(arm.passive_force(), 0.0)
    damped = _arm("two", "base", "tool", TWO_LOCKED, damping=True)
    damped.set_state([0.3, -0.2], [1.5, -2.0])
    np.testing.assert_allclose(damped.passive_force(), [-0.5 * 1.5, 0.0], atol=1e-15)
    assert not np.any(damped.model.dof_frictionloss)
    rubbing = _arm("two", "base", "tool", TWO_LOCKED, damping=True, friction=True,
                   friction_velocity=0.5)  # -F tanh(qdot / v_s) explicit, not frictionloss
    rubbing.set_state([0.3, -0.2], [1.5, -2.0])
    np.testing.assert_allclose(rubbing.passive_force(),
                               [-0.5 * 1.5 - 0.2 * np.tanh(1.5 / 0.5), 0.0], atol=1e-15)
    assert not np.any(rubbing.model.dof_frictionloss) and mujoco.get_mjcb_passive() is None
    xarm = _arm("xarm7", "world", "link_eef", {}, damping=True)  # damping 10/10/5/5/5/2/2
    velocity = np.linspace(-1.0, 1.0, 7)
    xarm.set_state(np.zeros(7), velocity)
    np.testing.assert_allclose(xarm.passive_force(), -xarm.chain.damping * velocity, atol=1e-14)


def test_urdf_is_cut_to_the_chain() -> None:
    """Meshes gone, the dropped branch gone, the locked finger fixed at its value (MuJoCo's body
    of the finger then sits where ours does)."""
    chain = read_urdf_chain(TWO_JOINTS, "base", "tool", TWO_LOCKED)
    text = chain_urdf(TWO_JOINTS.replace(
        '<link name="tool"/>',
        '<link name="tool"><visual><geometry><mesh filename="package://x/y.dae"/></geometry>'
        '</visual><collision><geometry><mesh filename="package://x/y.dae"/></geometry>'
        '</collision></link>'), chain)
    assert "mesh" not in text and "antenna" not in text and 'name="world"' not in text
    assert '<joint name="finger_joint" type="fixed">' in text
    model = _arm("two", "base", "tool", TWO_LOCKED).model
    assert model.nv == 2


def test_period_must_be_a_multiple_of_the_step() -> None:
    with pytest.raises(UrdfError, match="must divide the control period"):
        _arm("two", "base", "tool", TWO_LOCKED, timestep=0.003, period=0.01)
