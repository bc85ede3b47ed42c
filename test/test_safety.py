"""Safety in the loop: error envelope and safe hold, effort limits and saturation, watchdog."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trial_oracle import simulate_trial

from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.errors import SafetyError
from exo_ilc_ros.core.loop.controller import outside_envelope, safe_hold_effort
from exo_ilc_ros.core.loop.plant import clamp_counted, saturation_counts
from exo_ilc_ros.core.loop.safety import Watchdog, WatchdogState
from exo_ilc_ros.core.sim.experiment import Experiment

CONFIG = load_config()
TIGHT = CONFIG.replace({"safety.error_envelope": [0.1, 0.1, 0.1]})


def test_guarded_trial_is_bit_identical_to_the_plain_kernel() -> None:
    e = Experiment(CONFIG.with_mass_uncertainty(0.15))
    ref = e.reference
    u_ff = np.zeros_like(ref.position)
    plain = simulate_trial(u_ff, ref.position, ref.velocity, e.kp, e.kd, e.effort_limit,
                           e.period, e.substeps, e.plant.kernel_args, e.nominal.kernel_args,
                           int(e.dynamics))
    record = e.run_trial(u_ff, 1)
    assert record.aborted_at is None
    for a, b in zip(plain, (record.position, record.velocity, record.control_input,
                            record.effort), strict=True):
        assert np.array_equal(a, b)
    assert record.max_abs_error.max() < CONFIG["safety.error_envelope"][0]


def test_envelope_aborts_at_the_first_sample_outside_and_holds() -> None:
    e = Experiment(TIGHT)
    record = e.run_trial(np.zeros_like(e.reference.position), 1)
    k = record.aborted_at
    assert k is not None and record.aborted
    env = np.asarray(TIGHT["safety.error_envelope"])
    assert np.all(np.abs(record.error[:k]) <= env)
    assert np.any(np.abs(record.error[k]) > env)
    q_hold = record.position[k]
    assert e.hold_ramp == 5  # safety.hold_ramp 0.05 s at 0.01 s
    hold = np.array([e.hold_kp, e.hold_kd])
    ramp = {k: np.array([e.kp, e.kd]),  # the safe hold from the abort sample on, its gains
            k + 1: np.array([e.kp, e.kd]) + 0.2 * (hold - np.array([e.kp, e.kd])),  # ramped
            k + 5: hold, len(record.effort) - 1: hold}
    for i, (kp, kd) in ramp.items():
        expect = safe_hold_effort(q_hold, record.position[i], record.velocity[i], kp, kd,
                                  e.nominal.kernel_args, e.effort_limit)
        assert np.array_equal(record.effort[i], expect)
    # the arm comes to rest near the abort pose (gravity compensated, PD-damped)
    assert np.all(np.abs(record.velocity[-1]) < 0.05)
    assert np.all(np.abs(record.position[-1] - q_hold) < 0.2)
    # max |e| of an aborted trial covers the tracking part only
    assert np.array_equal(record.max_abs_error, np.max(np.abs(record.error[:k + 1]), axis=0))


def test_aborted_trial_is_learned_from_up_to_the_abort_only() -> None:
    """Rule 2 of core/session/learning_session.py (test_abort_learning.py has the update by
    hand): the feed-forward after an abort differs before the abort sample, not after it."""
    result = run_trials(TIGHT, trials=3)
    assert result.aborted == [1, 2, 3]
    first, second = result.records[0], result.records[1]
    a = first.aborted_at
    assert a is not None
    assert not np.array_equal(first.feedforward[:a], second.feedforward[:a])
    assert np.array_equal(first.feedforward[a:], second.feedforward[a:])


def test_shipped_envelope_does_not_touch_the_papers_first_trials() -> None:
    for delta in (0.05, 0.10, 0.15):
        result = run_trials(CONFIG, delta, trials=3)
        assert result.aborted == []


@pytest.mark.slow
def test_shipped_envelope_does_not_abort_the_papers_experiment() -> None:
    result = run_trials(CONFIG, 0.05)  # the shipped 150 trials: peak 0.54 rad (elbow)
    assert result.aborted == []
    assert result.max_abs_errors.max() < CONFIG["safety.error_envelope"][2]


def test_nan_feedforward_is_refused() -> None:
    e = Experiment(CONFIG)
    u_ff = np.zeros_like(e.reference.position)
    u_ff[10, 1] = math.nan
    with pytest.raises(SafetyError, match="non-finite"):
        e.run_trial(u_ff, 4)


def test_outside_envelope() -> None:
    env = np.array([0.3, 0.3, 0.3])
    zero = np.zeros(3)
    assert not outside_envelope(np.array([0.3, -0.3, 0.0]), zero, env)
    assert outside_envelope(np.array([0.0, -0.31, 0.0]), zero, env)
    assert outside_envelope(zero, np.array([0.0, 0.31, 0.0]), env)
    assert outside_envelope(np.array([math.nan, 0.0, 0.0]), zero, env)
    assert outside_envelope(zero, np.array([0.0, math.inf, 0.0]), env)


def test_effort_never_exceeds_the_limit_even_for_a_diverging_feedforward() -> None:
    e = Experiment(CONFIG)
    u_ff = np.full_like(e.reference.position, 1e6)
    record = e.run_trial(u_ff, 1)
    assert np.all(np.abs(record.effort) <= e.effort_limit)
    assert saturation_counts(record.effort, e.effort_limit).min() >= 1


def test_plant_clamp_and_saturation_count() -> None:
    """The plant's clamp: beyond the limit clamped and counted as beyond, at the limit only
    counted as saturated, a non-finite command refused without writing or counting."""
    limit = np.array([40.0, 40.0, 20.0])
    saturated = np.zeros(3, dtype=np.int64)
    out = np.zeros(3)
    assert clamp_counted(np.array([50.0, -10.0, -20.0]), limit, saturated, out) == 1
    assert out.tolist() == [40.0, -10.0, -20.0]
    assert saturated.tolist() == [1, 0, 1]
    assert clamp_counted(np.array([0.0, -math.inf, 0.0]), limit, saturated, out) == -1
    assert clamp_counted(np.array([math.nan, 0.0, 0.0]), limit, saturated, out) == -1
    assert out.tolist() == [40.0, -10.0, -20.0] and saturated.tolist() == [1, 0, 1]
    log = np.array([[50.0, -10.0, -20.0], [0.0, -41.0, 19.0]])
    assert saturation_counts(log, limit).tolist() == [1, 1, 1]


def test_watchdog_trips_after_the_timeout_and_latches() -> None:
    period = 10_000_000
    dog = Watchdog(3, period)
    assert dog.state is WatchdogState.IDLE
    assert not dog.feed(0) and not dog.check(10**12)  # idle: nothing expected
    dog.arm(0)
    for i in range(1, 20):  # on time
        assert dog.feed(i * period)
        assert not dog.check(i * period + period // 2)
    last = 19 * period
    assert not dog.check(last + 3 * period)  # exactly the timeout: still fine
    assert dog.check(last + 3 * period + 1)  # just over: trips, reported once
    assert dog.tripped and not dog.check(last + 10 * period)
    assert not dog.feed(last + 11 * period)  # late input ignored, stays tripped
    assert dog.tripped and dog.trips == 1 and dog.late == 1
    dog.arm(last + 20 * period)  # next trial
    assert dog.state is WatchdogState.RUNNING and dog.feed(last + 21 * period)
    dog.disarm()
    assert dog.state is WatchdogState.IDLE and not dog.check(10**15)
    assert ("trips", "1") in dog.as_values()


def test_watchdog_late_feed_trips_it() -> None:
    dog = Watchdog(2, 100)
    dog.arm(0)
    assert not dog.feed(201)  # a gap longer than the timeout is a trip even if input resumes
    assert dog.tripped


def test_watchdog_rejects_nonsense() -> None:
    with pytest.raises(ValueError, match="periods"):
        Watchdog(0, 10)
