"""The arm in MuJoCo (core/sim/mujoco_arm.py) against the Rodriguez dynamics of
core/arm/dynamics.py: an independent engine on the MJCF generated from the same config."""

from __future__ import annotations

import numpy as np
import pytest

from exo_ilc_ros.core import Experiment, load_config
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.arm.model import ArmModel, with_mass_scale
from exo_ilc_ros.core.errors import ModelError
from exo_ilc_ros.core.loop.stepper import PlantStepper
from exo_ilc_ros.core.sim.mujoco_arm import JointEffects, MujocoArm, arm_mjcf


@pytest.mark.parametrize("delta", [0.0, 0.15])
def test_inertia_and_bias_agree_with_rodriguez_at_1000_states(delta: float) -> None:
    """mj_fullM and qfrc_bias against a(q) and c(q, qdot) of eqs (2), (7) at 1000 random
    states (|q| <= pi, |qdot| <= 5 rad/s): relative difference (max entry over the largest
    entry) <= 1e-9. Measured: ~2e-15, rounding."""
    config = load_config(overrides={"mass_uncertainty": delta})
    arm = with_mass_scale(build_arm(config), delta)
    mujoco_arm = MujocoArm.from_config(config)
    rng = np.random.default_rng(15)
    worst_mass = worst_bias = 0.0
    for _ in range(1000):
        q, qd = rng.uniform(-np.pi, np.pi, 3), rng.uniform(-5.0, 5.0, 3)
        mass, bias = mujoco_arm.inertia_and_bias(q, qd)
        a, c = arm.metric_tensor(q), arm.bias_forces(q, qd)
        worst_mass = max(worst_mass, np.abs(mass - a).max() / np.abs(a).max())
        worst_bias = max(worst_bias, np.abs(bias - c).max() / np.abs(c).max())
    assert worst_mass <= 1e-9 and worst_bias <= 1e-9, (worst_mass, worst_bias)


def test_stepping_agrees_with_our_plant() -> None:
    """500 control periods of a varying effort, MuJoCo's RK4 against ours at the same step:
    the same method, so they agree to rounding (measured ~3e-15 rad)."""
    config = load_config(overrides={"mass_uncertainty": 0.1})
    ours = PlantStepper(Experiment(config))
    theirs = MujocoArm.from_config(config)
    theirs.set_state(ours.position, ours.velocity)
    for k in range(500):
        effort = np.array([3.0 * np.sin(0.02 * k), 1.0, 0.5 * np.cos(0.05 * k)])
        ours.step(effort)
        theirs.step(effort)
    np.testing.assert_allclose(theirs.position, ours.position, rtol=0, atol=1e-10)
    np.testing.assert_allclose(theirs.velocity, ours.velocity, rtol=0, atol=1e-10)
    assert theirs.time == pytest.approx(5.0)


def test_effort_is_clamped_and_counted_and_bad_effort_refused() -> None:
    config = load_config()
    arm = MujocoArm.from_config(config)
    saturated = np.zeros(3, dtype=np.int64)
    assert arm.step(np.array([100.0, 0.0, -100.0]), saturated) == 2
    np.testing.assert_array_equal(arm.applied, [40.0, 0.0, -20.0])
    np.testing.assert_array_equal(saturated, [1, 0, 1])
    before = arm.position
    assert arm.step(np.array([np.nan, 0.0, 0.0])) == -1
    assert arm.step(np.zeros(2)) == -1
    np.testing.assert_array_equal(arm.position, before)


def test_mjcf_merges_the_fictive_link_and_maps_joint_effects() -> None:
    """The zero-mass zero-length shoulder link is no body of its own (MuJoCo refuses massless
    moving bodies): both shoulder hinges sit in the upper-arm body, in chain order. Native
    joint effects appear as joint attributes; a massless link with length is refused."""
    config = load_config()
    arm = build_arm(config)
    names = config["joint_names"]
    xml = arm_mjcf(arm, names, 0.001, JointEffects(damping=[0.0, 0.3, 0.0],
                                                    armature=[0.01, 0.0, 0.0]))
    assert xml.count("<body ") == 2 and "link_1" not in xml
    first = xml.index(f'name="{names[0]}"')
    assert first < xml.index(f'name="{names[1]}"') < xml.index('<body name="link_3"')
    assert 'damping="0.3"' in xml and 'armature="0.01"' in xml
    assert xml.count("damping=") == 1 and "frictionloss" not in xml
    with_effects = MujocoArm(arm, names, 0.01, 0.001, [40.0] * 3,
                             JointEffects(damping=[0.0, 0.3, 0.0]))
    np.testing.assert_allclose(with_effects.model.dof_damping, [0.0, 0.3, 0.0])
    bad = ArmModel.from_links([0.0, 0.0, 1.0], [0.0, 0.2, 0.3], [0.0, 0.0, 0.04],
                              [0.0, 0.0, 0.03], ["x", "y", "x"])
    with pytest.raises(ModelError, match="link 2 has no mass"):
        arm_mjcf(bad, names, 0.001)


def test_patient_keys_map_to_native_joint_effects() -> None:
    """The MuJoCo arm takes the virtual patient's viscous friction (+ spastic damping) as
    ``damping``, Coulomb friction as ``frictionloss``, passive (+ spastic) stiffness towards the
    rest position as a joint spring: MuJoCo's passive force is then -B qdot - K (q - q_0), by
    hand; a MAS preset gives its stiffness and damping; the shipped config has no effect; what
    MuJoCo cannot express is named."""
    from exo_ilc_ros.core.loop.patient import MAS_PRESETS
    from exo_ilc_ros.core.sim.mujoco_arm import effects_from_config, effects_not_simulated

    config = load_config()
    arm = build_arm(config)
    names = config["joint_names"]
    assert arm_mjcf(arm, names, 0.001, effects_from_config(config)) == arm_mjcf(arm, names, 0.001)
    assert effects_not_simulated(config) == []
    patient = config.replace({"patient.friction.viscous": [0.05, 0.0, 0.02],
                              "patient.spasticity.damping": [0.0, 0.0, 0.1],
                              "patient.friction.coulomb": [0.1, 0.0, 0.0],
                              "patient.passive.stiffness": [0.0, 0.5, 1.0],
                              "patient.spasticity.stiffness": [0.0, 0.0, 2.0],
                              "patient.passive.rest_position": [0.0, 0.1, 0.3]})
    effects = effects_from_config(patient)
    np.testing.assert_allclose(effects.damping, [0.05, 0.0, 0.12])
    np.testing.assert_allclose(effects.stiffness, [0.0, 0.5, 3.0])
    mujoco_arm = MujocoArm(arm, names, 0.01, 0.001, [40.0] * 3, effects)
    np.testing.assert_allclose(mujoco_arm.model.dof_frictionloss, [0.1, 0.0, 0.0])
    q, qd = np.array([0.2, -0.3, 0.5]), np.array([1.0, -2.0, 0.5])
    mujoco_arm.set_state(q, qd)
    np.testing.assert_allclose(mujoco_arm.data.qfrc_passive,
                               -np.array([0.05, 0.0, 0.12]) * qd
                               - np.array([0.0, 0.5, 3.0]) * (q - np.array([0.0, 0.1, 0.3])),
                               rtol=1e-12, atol=1e-15)
    graded = config.replace({"patient.spasticity.mas_grade": "2"})
    k, b, _, _, _ = MAS_PRESETS["2"]
    np.testing.assert_allclose(effects_from_config(graded).stiffness, [k] * 3)
    np.testing.assert_allclose(effects_from_config(graded).damping, [b] * 3)
    assert effects_not_simulated(graded) == ["spasticity reflex"]
    noisy = config.replace({"patient.sensor.position_noise": 1e-4,
                            "patient.effort_delay": 2})
    assert effects_not_simulated(noisy) == ["effort delay", "sensors"]
