"""Learning through an abort (core/session/abort.py): the partial update computed by hand, an
aborted feed-forward never run again, a trial-1 abort learned from, the stop after aborts in a
row (in-process and through the CLI, exit 5), resume == uninterrupted, graph == in-process."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core import ConfigError, Experiment, LearningSession, StopReason, load_config
from exo_ilc_ros.core.params.config import Config
from exo_ilc_ros.core.session.abort import (
    ABORT_STOP_KEY,
    DIVERGED_CAUSE,
    abort_trip,
    pass_length_record,
)
from exo_ilc_ros.core.session.learning_session import run_trials

SHORT = {"trajectory.duration": 1.0}
TIGHT = {**SHORT, "safety.error_envelope": 0.05}
"""PD alone leaves this envelope in trial 1 (shoulder, about 0.2 s in): an abort from trial 1."""


def _config(**overrides: Any) -> Config:
    return load_config(overrides={**SHORT, **overrides})


def _linear(**overrides: Any) -> Config:
    """The linear law u_ff,k+1 = u_ff,k + G_p e_k (memory feedforward, no Q-filter): an update
    that can be written out by hand sample by sample."""
    return _config(law="linear", memory="feedforward", **{
        "linear.gain_position": [30.0, 20.0, 10.0], "linear.gain_velocity": 0.0,
        "linear.gain_acceleration": 0.0}, **overrides)


def test_partial_update_by_hand() -> None:
    """The law's update on [0, a), the aborted feed-forward from a on, the tripping joint's
    change times the back-off."""
    config = _linear(**{"abort.backoff": 0.5})
    session = LearningSession(config)
    experiment = Experiment(config)
    first = experiment.run_trial(session.feedforward, 1)
    a = 37
    aborted = replace(first, aborted_at=a)
    tripped = abort_trip(1, a, aborted.max_abs_error, config).tripped
    assert len(tripped) == 1  # inside the envelope: the joint furthest out, alone
    conclusion = session.conclude(aborted)
    assert conclusion.learned and conclusion.trip is not None
    assert session.consecutive_aborts == 1 and session.aborted_trials == [1]
    ff, e = first.feedforward, first.error
    gains = np.array([30.0, 20.0, 10.0])
    expected = ff.copy()
    for t in range(a):
        for j in range(3):
            step = gains[j] * e[t, j]
            expected[t, j] = ff[t, j] + (0.5 * step if j in tripped else step)
    np.testing.assert_allclose(session.feedforward, expected, rtol=0.0, atol=1e-15)
    np.testing.assert_array_equal(session.feedforward[a:], ff[a:])  # the rest as it was
    assert not np.array_equal(session.feedforward, ff)


def test_pass_length_record_reads_only_the_samples_the_trial_had() -> None:
    config = _config()
    experiment = Experiment(config)
    record = experiment.run_trial(np.zeros_like(experiment.reference.position), 1)
    a = 20
    shortened = pass_length_record(replace(record, aborted_at=a))
    assert not shortened.aborted
    np.testing.assert_array_equal(shortened.error[:a + 1], record.error[:a + 1])
    np.testing.assert_array_equal(shortened.error[a + 1:], 0.0)
    np.testing.assert_array_equal(shortened.error_velocity[a + 1:], 0.0)
    np.testing.assert_array_equal(shortened.control_input[a + 1:], record.feedforward[a + 1:])
    assert pass_length_record(record) is record  # a completed trial as it is


def test_trial_one_abort_learns_and_no_aborted_feedforward_repeats() -> None:
    """PD alone leaves the envelope in trial 1: trial 2 runs another feed-forward; no trial
    after an abort runs the aborted one; three in a row stop the run with one message."""
    config = _config(**TIGHT, max_trials=20)
    result = run_trials(config)
    records = result.records
    assert records[0].aborted
    for before, after in itertools.pairwise(records):
        if before.aborted:
            assert not np.array_equal(before.feedforward, after.feedforward), after.trial
    assert result.stop is StopReason.ABORTS and len(records) == 3
    message = result.stop_message
    last = records[-1]
    joint = int(np.argmax(last.max_abs_error))
    name = config["joint_names"][joint]
    time = last.aborted_at * config["control.period"]
    assert message.startswith("stopped after 3 aborted trials in a row: trial 3: "
                              f"{name} left the error envelope at t = {time:.3f} s "
                              f"(|e| {last.max_abs_error[joint]:.4f} > 0.0500 rad)"), message
    assert "likely cause" in message
    # the learning pushed the abort later each time (the envelope is reached later)
    assert [r.aborted_at for r in records] == sorted(r.aborted_at for r in records)


def test_max_consecutive_counts_aborts_in_a_row_only() -> None:
    config = _config(**TIGHT, max_trials=20, **{"abort.max_consecutive": 5})
    result = run_trials(config)
    assert len(result.records) == 5 and result.stop is StopReason.ABORTS
    assert "5 aborted trials in a row" in result.stop_message


def test_abort_keys_are_validated() -> None:
    with pytest.raises(ConfigError, match=r"abort\.backoff"):
        _config(**{"abort.backoff": 1.5})
    with pytest.raises(ConfigError, match=r"abort\.backoff"):
        _config(**{"abort.backoff": 0.0})
    with pytest.raises(ConfigError, match=r"abort\.max_consecutive"):
        _config(**{"abort.max_consecutive": 0})


def test_an_abort_with_nothing_measured_stops_at_once() -> None:
    """An abort at sample 0: no valid sample, nothing learned, the same feed-forward would run
    again: the session stops now, saying so."""
    config = _linear()
    session = LearningSession(config)
    record = replace(Experiment(config).run_trial(session.feedforward, 1), aborted_at=0)
    conclusion = session.conclude(record)
    np.testing.assert_array_equal(conclusion.update.feedforward, record.feedforward)
    assert not conclusion.learned and session.stop is StopReason.ABORTS
    assert session.stop_message.startswith("stopped after an aborted trial: trial 1: ")
    assert "nothing was measured before the abort" in session.stop_message


def test_a_diverged_plant_stops_at_once_with_its_cause() -> None:
    config = _config()
    session = LearningSession(config)
    record = Experiment(config).run_trial(session.feedforward, 1)
    position = record.position.copy()
    position[30:, 1] = np.nan
    diverged = replace(record, position=position, aborted_at=30)
    conclusion = session.conclude(diverged)
    assert session.stop is StopReason.ABORTS
    assert conclusion.stop_message == session.stop_message
    assert f"the plant diverged at t = 0.300 s on {config['joint_names'][1]}" in \
        session.stop_message
    assert DIVERGED_CAUSE in session.stop_message
    assert np.all(np.isfinite(session.feedforward))  # nothing non-finite learned


def test_resume_after_aborts_equals_the_uninterrupted_run(tmp_path: Path) -> None:
    """Stopped after trial 2 (two aborts: the count towards the stop) and resumed: the same trials,
    feed-forwards and stop, bit for bit."""
    config = _config(**TIGHT, max_trials=20, **{"abort.max_consecutive": 4})
    whole = run_trials(config, store=tmp_path / "whole")
    part = run_trials(config, trials=2, store=tmp_path / "part")
    assert part.aborted == [1, 2] and part.stop is StopReason.MAX_TRIALS
    resumed = run_trials(config, store=tmp_path / "part", resume=True)
    assert resumed.resumed == 2
    assert [r.trial for r in resumed.records] == [r.trial for r in whole.records] == [1, 2, 3, 4]
    for a, b in zip(resumed.records, whole.records, strict=True):
        np.testing.assert_array_equal(a.feedforward, b.feedforward)
        np.testing.assert_array_equal(a.position, b.position)
        assert a.aborted_at == b.aborted_at
    assert resumed.final is not None and whole.final is not None
    np.testing.assert_array_equal(resumed.final.feedforward, whole.final.feedforward)
    assert resumed.stop is whole.stop is StopReason.ABORTS
    assert resumed.stop_message == whole.stop_message
    # resuming a run that stopped: stopped again at once, with the same message
    again = run_trials(config, store=tmp_path / "whole", resume=True)
    assert again.resumed == 4 and len(again.records) == 4
    assert again.stop_message == whole.stop_message


def test_raising_the_limit_and_resuming_continues_as_if_never_stopped(tmp_path: Path) -> None:
    """A run stopped after 3 aborts in a row, resumed with ``abort.max_consecutive`` 5 (not in
    the store's key): the trials of an uninterrupted run with 5, bit for bit."""
    config = _config(**TIGHT, max_trials=20)
    stopped = run_trials(config, store=tmp_path)
    assert len(stopped.records) == 3 and stopped.stop is StopReason.ABORTS
    raised = config.replace({"abort.max_consecutive": 5})
    resumed = run_trials(raised, store=tmp_path, resume=True)
    whole = run_trials(raised)
    assert resumed.resumed == 3 and len(resumed.records) == len(whole.records) == 5
    for a, b in zip(resumed.records, whole.records, strict=True):
        np.testing.assert_array_equal(a.feedforward, b.feedforward)
        np.testing.assert_array_equal(a.position, b.position)
    assert resumed.stop_message == whole.stop_message != stopped.stop_message


def test_simulate_cli_stops_with_the_message_and_exit_5(tmp_path: Path) -> None:
    config_file = tmp_path / "tight.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'
                           '    safety:\n      error_envelope: 0.05\n')
    out = tmp_path / "run.json"
    result = subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", "simulate",
                             "--config", str(config_file), "--trials", "20", "--quiet",
                             "--json", str(out)], text=True, capture_output=True,
                            timeout=300, check=False)
    assert result.returncode == 5, result.stderr[-3000:]
    assert result.stderr.count("stopped after 3 aborted trials in a row") == 1, result.stderr
    assert "exit 5" in result.stderr
    run = json.loads(out.read_text())["runs"][0]
    assert len(run["trials"]) == 3 and run["aborted_trials"] == [1, 2, 3]
    assert run[ABORT_STOP_KEY].startswith("stopped after 3 aborted trials in a row")


@pytest.mark.graph
def test_graph_equals_in_process_through_aborts() -> None:
    """The supervisor's session learns through the same aborts: the same trials, errors and
    stop message as in-process."""
    from exo_ilc_ros.orchestration.graph import run_graph

    config = _config(**TIGHT, max_trials=20)
    local = run_trials(config)
    graph = run_graph(config, timeout=300.0)
    assert [s.trial for s in graph.summaries] == [r.trial for r in local.records]
    np.testing.assert_allclose(graph.summary.max_abs_error, local.max_abs_errors,
                               rtol=0.0, atol=1e-9)
    assert graph.summary.extra.get("aborted_trials") == local.aborted
    assert graph.summary.extra.get(ABORT_STOP_KEY) == local.stop_message


def test_a_therapy_session_stops_with_the_exercise(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``simulate --patient --session``: the first exercise stops after three aborts in a row
    (saved to the profile with its partial learning), the second is not run, exit 5."""
    from exo_ilc_ros.cli.main import main
    from exo_ilc_ros.core.persistence.profiles import ProfileBook

    exercises = tmp_path / "exercises.yaml"
    exercises.write_text(
        "exercises:\n  up: {points: [[0, 0, 0], [0.6, 0.4, 0.4]], durations: [0.5]}\n"
        "  down: {points: [[0.6, 0.4, 0.4], [0, 0, 0]], durations: [0.5]}\n"
        "sessions:\n  short: [{exercise: up, trials: 6}, {exercise: down, trials: 2}]\n")
    config = tmp_path / "c.yaml"
    config.write_text(f'"/**":\n  ros__parameters:\n    exercise:\n      file: "{exercises}"\n'
                      '    safety:\n      error_envelope: 0.005\n')
    assert main(["simulate", "--config", str(config), "--profiles", str(tmp_path / "p"),
                 "--quiet", "--patient", "p1", "--new-patient", "--session", "short"]) == 5
    err = capsys.readouterr().err
    assert err.count("stopped after 3 aborted trials in a row") == 1, err
    assert "the session stops here" in err and "1 exercise not run" in err
    book = ProfileBook(tmp_path / "p")
    assert book.exercises("p1") == ["up"]
    assert book.load("p1", "up").provenance["trials"] == 3


@pytest.mark.graph
def test_run_cli_through_the_graph_stops_with_the_message_and_exit_5(tmp_path: Path) -> None:
    config_file = tmp_path / "tight.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'
                           '    safety:\n      error_envelope: 0.05\n')
    out = tmp_path / "run.json"
    result = subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", "run", "--no-bag",
                             "--config", str(config_file), "--trials", "20", "--quiet",
                             "--json", str(out)], text=True, capture_output=True,
                            timeout=300, check=False, cwd=tmp_path)
    assert result.returncode == 5, result.stderr[-3000:]
    local = run_trials(_config(**TIGHT, max_trials=20))
    assert result.stderr.count(local.stop_message) == 1, result.stderr[-3000:]
    run = json.loads(out.read_text())["runs"][0]
    assert run["aborted_trials"] == local.aborted == [1, 2, 3]
    assert run[ABORT_STOP_KEY] == local.stop_message


@pytest.mark.graph
def test_graph_resume_of_a_stopped_run_stops_again_with_the_message(tmp_path: Path) -> None:
    """A store whose last trials stopped the run (in-process), resumed through the graph: no
    trial runs, the run carries the same stop message (``exo-ilc run`` exits 5 on it)."""
    from exo_ilc_ros.orchestration.graph import run_graph

    config = _config(**TIGHT, max_trials=20)
    local = run_trials(config, store=tmp_path)
    assert local.stop is StopReason.ABORTS
    resumed = run_graph(config.replace({"store.directory": str(tmp_path),
                                        "store.resume": True}), timeout=300.0)
    assert [s.trial for s in resumed.summaries] == [1, 2, 3]
    assert resumed.summary.extra.get(ABORT_STOP_KEY) == local.stop_message
    np.testing.assert_allclose(resumed.summary.max_abs_error, local.max_abs_errors,
                               rtol=0.0, atol=1e-12)


@pytest.mark.graph
def test_robust_on_the_stiff_patient_through_the_graph_as_in_process() -> None:
    """robust.yaml on the stiff patient (issue 33, point 1), the supervisor's session over real
    DDS: no aborted trial runs its feed-forward again (every learned profile after an abort
    differs from the aborted one), and the run stops after 3 aborts in a row with the same
    trials, errors, aborts and message as in-process (21 trials, aborts 16, 17, 19, 20, 21)."""
    from exo_ilc_ros.core.params.config import config_dir
    from exo_ilc_ros.orchestration.graph import run_graph

    config = load_config(config_dir() / "robust.yaml", {"max_trials": 60},
                         overlays=[config_dir() / "scenarios" / "stiff.yaml"])
    local = run_trials(config)
    records = local.records
    assert local.stop is StopReason.ABORTS and local.aborted == [16, 17, 19, 20, 21]
    for before, after in itertools.pairwise(records):
        if before.aborted:
            assert not np.array_equal(before.feedforward, after.feedforward), after.trial
    graph = run_graph(config, timeout=600.0)
    assert [s.trial for s in graph.summaries] == [r.trial for r in records]
    np.testing.assert_allclose(graph.summary.max_abs_error, local.max_abs_errors,
                               rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(graph.summary.max_abs_feedforward,
                               local.max_abs_feedforward, rtol=0.0, atol=1e-9)
    assert graph.summary.extra.get("aborted_trials") == local.aborted
    assert graph.summary.extra.get(ABORT_STOP_KEY) == local.stop_message
    # (a trial the graph ran again, "reruns", is a watchdog trip or lost samples on a loaded
    # machine: its rerun is what the trials above compare, so it is no failure here)
