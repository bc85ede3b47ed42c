"""The safe hold's own gains (core/loop/hold.py): its effort by hand, the ramp, the stability rule,
and that it brings a spastic arm to rest after an abort where the controller's gains did not."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.loop.controller import GuardedControlStep, safe_hold_effort
from exo_ilc_ros.core.loop.hold import REST_SPEED, hold_gains_into, rest_after_abort
from exo_ilc_ros.core.loop.trial import record_from_samples
from exo_ilc_ros.core.params.config import load_config, scenario_path
from exo_ilc_ros.core.params.hold_rule import hold_radius
from exo_ilc_ros.core.sim.experiment import Experiment

CONTROLLER_GAINS = {"safety.hold_kp": [16.0, 10.0, 10.0], "safety.hold_kd": [8.0, 5.0, 7.0],
                    "safety.hold_ramp": 0.0}
"""The safe hold as it was before ``safety.hold_*``: the controller's own gains, no ramp."""
REST_WITHIN = 2.0
"""s after the abort by which the arm must be at rest (docs/reliability.md's definition)."""
BRAKING = 0.5
"""rad: how far from the latched pose the arm may get while the hold stops it."""


def _spastic(**overrides: Any) -> Any:
    return load_config(overlays=[scenario_path("spastic")],
                       overrides={"mass_uncertainty": 0.1, **overrides})


def _abort(config: Any, joint: int, drive: float) -> tuple[Experiment, Any]:
    """Trial 1 with a constant feed-forward ``drive`` (rad/s^2) on ``joint``: the arm leaves
    the error envelope fast, and the safe hold runs for the rest of the trial."""
    ex = Experiment(config)
    u_ff = np.zeros_like(ex.reference.position)
    u_ff[:, joint] = drive
    record = ex.run_trial(u_ff, 1)
    assert record.aborted_at is not None and record.aborted_at < 100
    return ex, record


def test_hold_effort_by_hand_on_a_rod_forearm() -> None:
    """A massless upper arm (l1) and a uniform thin rod forearm (m, L): at q = (0, 0, q3),
    shoulder at its latched pose and still, the hold (after its ramp) is
    Q3 = I u3 + m g (L/2) sin q3, Q1 = (I + m l1 (L/2) cos q3) u3 + m g (L/2) sin q3
    - m l1 (L/2) sin q3 qdot3^2, Q2 = 0, with u3 = K_P,h (q_hold,3 - q3) - K_D,h qdot3 and
    I = m L^2 / 3; clamped to the limit."""
    m, length, l1, g = 1.5, 0.4, 0.3, 9.81
    config = load_config(overrides={
        "model.link_masses": [0.0, 0.0, m], "model.link_lengths": [0.0, l1, length],
        "model.radius_proximal": [0.0, 0.0, 1e-5], "model.radius_distal": [0.0, 0.0, 1e-5],
        "safety.hold_kp": [100.0, 100.0, 400.0], "safety.hold_kd": [20.0, 20.0, 30.0]})
    ex = Experiment(config)
    assert ex.hold_ramp == 5
    step = GuardedControlStep(ex)
    q3, e3, w3 = 0.7, 0.05, -0.8
    q = np.array([0.0, 0.0, q3])
    qd = np.array([0.0, 0.0, w3])
    step.hold_at(q + np.array([0.0, 0.0, e3]))
    for _ in range(5):  # the ramp's samples
        step.hold(q, qd)
    effort = step.hold(q, qd).copy()
    inertia, half = m * length ** 2 / 3.0, length / 2.0
    u3 = 400.0 * e3 - 30.0 * w3
    expected = [(inertia + m * l1 * half * math.cos(q3)) * u3 + m * g * half * math.sin(q3)
                - m * l1 * half * math.sin(q3) * w3 ** 2, 0.0,
                inertia * u3 + m * g * half * math.sin(q3)]
    np.testing.assert_allclose(effort, expected, rtol=1e-6, atol=1e-12)
    # far from the pose: clamped to the effort limit (40, 40, 20 N m), the sign of the error
    step.hold_at(q + np.array([0.0, 0.0, 10.0]))
    for _ in range(6):
        effort = step.hold(q, qd)
    assert effort[2] == 20.0 and effort[0] == 40.0 and abs(effort[1]) < 1e-12


def test_hold_gains_ramp_from_the_controllers_by_hand() -> None:
    """m = 0: the controller's gains; m = 1 of 4: a quarter of the way; m >= 4: exactly the
    hold's; a ramp of 0: the hold's at once."""
    kp, kd = np.array([16.0, 10.0]), np.array([8.0, 4.0])
    hold_kp, hold_kd = np.array([216.0, 410.0]), np.array([28.0, 64.0])
    out = np.empty((2, 2))
    hold_gains_into(0, 4, kp, kd, hold_kp, hold_kd, out)
    np.testing.assert_array_equal(out, [kp, kd])
    hold_gains_into(1, 4, kp, kd, hold_kp, hold_kd, out)
    np.testing.assert_array_equal(out, [[66.0, 110.0], [13.0, 19.0]])
    hold_gains_into(3, 4, kp, kd, hold_kp, hold_kd, out)
    np.testing.assert_array_equal(out, [[166.0, 310.0], [23.0, 49.0]])
    for m in (4, 5, 1000):
        hold_gains_into(m, 4, kp, kd, hold_kp, hold_kd, out)
        np.testing.assert_array_equal(out, [hold_kp, hold_kd])
    hold_gains_into(0, 0, kp, kd, hold_kp, hold_kd, out)
    np.testing.assert_array_equal(out, [hold_kp, hold_kd])


def test_hold_stability_rule_by_hand_and_in_the_schema() -> None:
    """Without delay the ZOH PD on a double integrator is stable iff K_D T < 2 (Jury:
    1 + tr + det = 4 - 2 K_D T): the radius crosses 1 there. The schema refuses hold gains that
    are not stable with the command one period late, naming the key and the rule, and takes
    the same gains at a shorter period."""
    assert hold_radius(100.0, 199.0, 0.01, 0) < 1.0 < hold_radius(100.0, 201.0, 0.01, 0)
    assert hold_radius(900.0, 60.0, 0.01, 1) < 1.0 < hold_radius(900.0, 60.0, 0.01, 2)
    with pytest.raises(ConfigError) as refused:
        load_config(overrides={"safety.hold_kp": [225.0, 225.0, 2500.0],
                               "safety.hold_kd": [30.0, 30.0, 100.0]})
    assert refused.value.key == "safety.hold_kd"
    assert "joint 3" in str(refused.value) and "not stable" in str(refused.value)
    fast = load_config(overrides={"control.period": 0.001,
                                  "safety.hold_kp": [225.0, 225.0, 2500.0],
                                  "safety.hold_kd": [30.0, 30.0, 100.0]})
    assert fast["safety.hold_kd"][2] == 100.0
    assert Experiment(fast).hold_ramp == 50  # 0.05 s at 1 kHz


@pytest.mark.parametrize(("joint", "drive"), [(2, 150.0), (0, 80.0)])
def test_spastic_arm_comes_to_rest_after_an_abort_only_with_the_hold_gains(
        joint: int, drive: float) -> None:
    """``spastic`` (MAS 2), 10 %: an abort with the arm moving fast. With the shipped hold the
    arm is at rest (every |qdot| < 0.05 rad/s) within 2 s and stops within 0.5 rad of the
    latched pose; with the controller's gains as the hold (the hold before ``safety.hold_*``)
    the reflex keeps it swinging at several rad/s to the trial's end."""
    ex, record = _abort(_spastic(), joint, drive)
    rest = rest_after_abort(record, ex.period)
    assert rest.at_rest and rest.time_to_rest <= REST_WITHIN
    assert rest.braking < BRAKING
    assert rest.peak_effort <= 40.0
    q_end = record.position[-1]
    assert np.all(np.abs(record.velocity[-1]) < REST_SPEED)
    assert np.all(np.abs(q_end - record.position[record.aborted_at]) < BRAKING)
    old_ex, old = _abort(_spastic(**CONTROLLER_GAINS), joint, drive)
    assert old.aborted_at == record.aborted_at  # the same trial up to the abort
    before = slice(0, record.aborted_at + 1)
    np.testing.assert_array_equal(old.position[before], record.position[before])
    swinging = rest_after_abort(old, old_ex.period)
    assert not swinging.at_rest and swinging.late_peak_speed > 5.0


def test_a_softer_elbow_hold_leaves_the_straight_arm_swinging() -> None:
    """Why the elbow needs 60 s^-1: aborted near the straight arm (shoulder driven), whose light
    coupled mode has an inertia ~0.01 kg m^2, a 40 s^-1 elbow hold is still slower than the
    reflex; the shipped 60 brings it to rest."""
    soft = _spastic(**{"safety.hold_kp": [225.0, 225.0, 400.0],
                       "safety.hold_kd": [30.0, 30.0, 40.0]})
    ex, record = _abort(soft, 0, 40.0)
    assert not rest_after_abort(record, ex.period).at_rest
    ex, record = _abort(_spastic(), 0, 40.0)
    assert rest_after_abort(record, ex.period).time_to_rest <= REST_WITHIN


def test_the_graph_rebuilds_and_the_node_commands_the_ramped_hold_bit_for_bit() -> None:
    """The aborted trial's efforts as the graph rebuilds them from samples
    (``record_from_samples``) and as the controller node forms them one sample at a time
    (``GuardedControlStep``, hold latched at the abort) equal the in-process trial's."""
    ex, record = _abort(_spastic(), 2, 150.0)
    rebuilt = record_from_samples(ex, 1, record.feedforward, record.position, record.velocity,
                                  aborted_at=record.aborted_at)
    assert np.array_equal(rebuilt.effort, record.effort)
    step = GuardedControlStep(ex)
    ref = ex.reference
    for i in range(ref.samples):
        q, qd = record.position[i], record.velocity[i]
        if i < record.aborted_at:
            effort = step(record.feedforward[i], ref.position[i], ref.velocity[i], q, qd)
        else:
            if i == record.aborted_at:
                assert step.outside(ref.position[i], q)
                step.hold_at(q)
            effort = step.hold(q, qd)
        assert np.array_equal(effort, record.effort[i]), i
    hold = safe_hold_effort(record.position[record.aborted_at], record.position[-1],
                            record.velocity[-1], ex.hold_kp, ex.hold_kd,
                            ex.nominal.kernel_args, ex.effort_limit)
    assert np.array_equal(hold, record.effort[-1])
