"""The learning session: the trial-to-trial rules both the in-process runner and the graph use,
checked on hand-made records and against a plain loop over the law."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core import (
    ConfigError,
    Experiment,
    LearningSession,
    StopReason,
    build_law,
    load_config,
    run_trials,
)
from exo_ilc_ros.core.errors import SafetyError, StoreError
from exo_ilc_ros.core.learning.laws import FeedforwardUpdate
from exo_ilc_ros.core.loop.record import TrialRecord

SHORT = {"trajectory.duration": 1.0}
CHANGE = {"schedule.position.threshold_low": [0.0, 0.0, 0.0]}


def _config(**overrides: object) -> object:
    return load_config(overrides={**SHORT, **overrides})


def _plain_loop(config: object, trials: int, changed: object | None = None,
                effective: int = 0) -> list[TrialRecord]:
    """The rules written out by hand: learn from every trial with the config's law (the
    changed config's from trial ``effective`` on)."""
    experiment = Experiment(config)  # type: ignore[arg-type]
    laws = [build_law(config), build_law(changed or config)]  # type: ignore[arg-type]
    update = FeedforwardUpdate(laws[0].initial_feedforward(experiment.reference), None)
    records = []
    for k in range(1, trials + 1):
        record = experiment.run_trial(update.feedforward, k, update.levels)
        records.append(record)
        update = laws[int(changed is not None and k + 1 >= effective)].update(record)
    return records


def test_run_trials_is_the_plain_loop() -> None:
    config = _config(max_trials=6)
    result = run_trials(config)
    expected = _plain_loop(config, 6)
    assert [r.trial for r in result.records] == list(range(1, 7))
    for got, want in zip(result.records, expected, strict=True):
        np.testing.assert_array_equal(got.position, want.position)
        np.testing.assert_array_equal(got.feedforward, want.feedforward)
    assert result.stop is StopReason.MAX_TRIALS


def test_stop_when_settled_stops_after_the_streak() -> None:
    """At 5 % the short reference settles at trial 14 on every joint (first within = settled),
    so ``stop_when_settled: 3`` stops after trial 16; the table equals the full run's head."""
    full = run_trials(_config(max_trials=30), 0.05)
    settled = run_trials(_config(max_trials=30, stop_when_settled=3), 0.05)
    first = max(full.iterations_to_bound().settled)  # type: ignore[type-var]
    assert first is not None
    assert len(settled.records) == first + 2
    assert settled.stop is StopReason.SETTLED
    np.testing.assert_array_equal(settled.max_abs_errors,
                                  full.max_abs_errors[:len(settled.records)])


def test_live_change_replays_at_its_effective_trial() -> None:
    """A change effective at trial 4 is learned with after trial 3: equal to the plain loop
    that switches laws there, and reported in ``applied``."""
    config = _config(max_trials=8)
    result = run_trials(config, changes={4: CHANGE})
    expected = _plain_loop(config, 8, config.replace(CHANGE), effective=4)
    np.testing.assert_array_equal(result.max_abs_errors,
                                  np.array([r.max_abs_error for r in expected]))
    assert result.applied == {4: CHANGE}
    np.testing.assert_array_equal(result.records[3].levels[0], [0.03, 0.05, 0.05])
    unchanged = run_trials(config)
    np.testing.assert_array_equal(result.max_abs_errors[:3], unchanged.max_abs_errors[:3])
    assert not np.array_equal(result.max_abs_errors[3:], unchanged.max_abs_errors[3:])


def test_stage_checks_the_change_now() -> None:
    session = LearningSession(_config())
    with pytest.raises(ConfigError, match="threshold"):
        session.stage({"schedule.position.threshold_low": [30.0, 2.0, 1.0]})
    with pytest.raises(ValueError, match="max_trials"):
        session.stage({"max_trials": 3})
    assert session.staged == {}


def test_envelope_abort_learns_up_to_the_abort_and_breaks_the_streak() -> None:
    """Rule 2 (core/session/abort.py): the aborted trial's feed-forward is kept from the abort
    sample on and learned from before it; test_abort_learning.py computes the update by hand."""
    config = _config(max_trials=10)
    session = LearningSession(config)
    experiment = Experiment(config)
    first = experiment.run_trial(session.feedforward, 1)
    session.conclude(first)
    learned = session.feedforward.copy()
    aborted = replace(experiment.run_trial(learned, 2, session.levels), aborted_at=7)
    conclusion = session.conclude(aborted)
    assert conclusion.learned and not conclusion.within_bound
    assert conclusion.trip is not None and conclusion.trip.sample == 7
    np.testing.assert_array_equal(session.feedforward[7:], learned[7:])
    assert not np.array_equal(session.feedforward[:7], learned[:7])
    assert session.trial == 3 and session.aborted_trials == [2] and session.within_streak == 0
    assert session.consecutive_aborts == 1 and not session.finished


def test_discard_runs_the_same_trial_again() -> None:
    session = LearningSession(_config())
    before = session.feedforward.copy()
    session.discard("watchdog")
    assert session.trial == 1 and session.retried == [(1, "watchdog")]
    np.testing.assert_array_equal(session.feedforward, before)


def test_a_bad_learned_feedforward_stops_and_changes_nothing() -> None:
    config = _config()
    experiment = Experiment(config)

    class Broken:
        def initial_feedforward(self, reference: object) -> np.ndarray:
            return np.zeros_like(experiment.reference.position)

        def update(self, record: TrialRecord) -> FeedforwardUpdate:
            bad = np.zeros_like(record.feedforward)
            bad[3, 1] = np.nan
            return FeedforwardUpdate(bad, None)

    session = LearningSession(config, Broken())
    record = experiment.run_trial(session.feedforward, 1)
    with pytest.raises(SafetyError, match="non-finite"):
        session.conclude(record)
    assert session.trial == 1 and session.completed == 0
    with pytest.raises(SafetyError, match="trial 2 concluded"):
        session.conclude(replace(record, trial=2))


def test_resume_restores_streak_and_stops_when_already_settled(tmp_path: Path) -> None:
    config = _config(max_trials=30, stop_when_settled=3)
    whole = run_trials(config, 0.05, store=tmp_path)
    session = LearningSession(config.replace({"mass_uncertainty": 0.05}))
    store, restored = session.open_store(tmp_path, resume=True)
    assert len(restored) == len(whole.records) == session.completed
    assert session.finished and session.stop is StopReason.SETTLED
    assert session.within_streak == 3
    fresh = LearningSession(config.replace({"mass_uncertainty": 0.05}))
    with pytest.raises(StoreError, match="already holds"):
        fresh.open_store(tmp_path, resume=False)
    assert store.completed == len(whole.records)
