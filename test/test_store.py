"""The store of learned data: atomic writes, keying, resume bit-identical (also after kill -9)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.errors import StoreError
from exo_ilc_ros.core.loop.record import TrialRecord
from exo_ilc_ros.core.persistence.store import RunStore, learning_key
from exo_ilc_ros.core.reference.build import build_reference
from exo_ilc_ros.core.session.result import RunResult

CONFIG = load_config()
TRIALS = 12


class SimulatedCrashError(Exception):
    """Stands for a crash between trials."""


def _same(a: RunResult, b: RunResult) -> None:
    assert len(a.records) == len(b.records)
    for x, y in zip(a.records, b.records, strict=True):
        assert x.trial == y.trial and x.aborted_at == y.aborted_at
        for name in ("position", "velocity", "feedforward", "control_input", "effort"):
            assert np.array_equal(getattr(x, name), getattr(y, name)), (x.trial, name)
        if x.levels is None or y.levels is None:
            assert x.levels is None and y.levels is None
        else:
            assert np.array_equal(x.levels, y.levels)
    assert a.final is not None and b.final is not None
    assert np.array_equal(a.final.feedforward, b.final.feedforward)
    assert np.array_equal(a.max_abs_errors, b.max_abs_errors)


def test_interrupted_run_resumes_bit_identical(tmp_path: Path) -> None:
    whole = run_trials(CONFIG, 0.1, TRIALS)

    def stop_after_5(record: TrialRecord) -> None:
        if record.trial == 5:
            raise SimulatedCrashError

    with pytest.raises(SimulatedCrashError):
        run_trials(CONFIG, 0.1, TRIALS, on_trial=stop_after_5, store=tmp_path)
    with pytest.raises(StoreError, match="already holds 5 trials"):
        run_trials(CONFIG, 0.1, TRIALS, store=tmp_path)
    resumed = run_trials(CONFIG, 0.1, TRIALS, store=tmp_path, resume=True)
    assert resumed.resumed == 5
    _same(whole, resumed)
    again = run_trials(CONFIG, 0.1, TRIALS, store=tmp_path, resume=True)  # nothing left to run
    assert again.resumed == TRIALS
    _same(whole, again)


def test_aborted_trials_are_stored_and_resumed(tmp_path: Path) -> None:
    tight = CONFIG.replace({"safety.error_envelope": [0.2, 0.2, 0.2]})
    whole = run_trials(tight, 0.15, 4)
    assert whole.aborted
    run_trials(tight, 0.15, 2, store=tmp_path)
    resumed = run_trials(tight, 0.15, 4, store=tmp_path, resume=True)
    _same(whole, resumed)
    index = json.loads(next(tmp_path.glob("*/index.json")).read_text())
    assert [t["aborted_at"] is not None for t in index["trials"]] == \
        [r.aborted for r in whole.records]


def test_leftovers_of_a_crash_are_ignored_and_corruption_detected(tmp_path: Path) -> None:
    run_trials(CONFIG, 0.05, 3, store=tmp_path)
    directory = next(tmp_path.iterdir())
    # a crash after trial 4's .npz was written but before the index named it
    (directory / "trial_0004.npz").write_bytes(b"half-written")
    (directory / ".index.json.12345.tmp").write_text("{")
    whole = run_trials(CONFIG, 0.05, 5)
    resumed = run_trials(CONFIG, 0.05, 5, store=tmp_path, resume=True)
    assert resumed.resumed == 3
    _same(whole, resumed)
    blob = bytearray((directory / "trial_0002.npz").read_bytes())
    blob[200] ^= 0xFF
    (directory / "trial_0002.npz").write_bytes(bytes(blob))
    with pytest.raises(StoreError, match=r"trial_0002\.npz: sha256"):
        run_trials(CONFIG, 0.05, 5, store=tmp_path, resume=True)


def test_key_covers_learning_not_live_or_run_control() -> None:
    ref = build_reference(CONFIG)
    key = learning_key(CONFIG, ref)
    same = CONFIG.replace({"max_trials": 7, "error_bound": 0.01, "mode": "real_time",
                           "safety.error_envelope": [0.5, 0.5, 0.5], "law": "linear"})
    assert learning_key(same, ref) == key
    for change in ({"mass_uncertainty": 0.1}, {"control.kp": [1.0, 1.0, 1.0]},
                   {"trajectory.duration": 4.0}, {"initial_feedforward":
                                                  "reference_acceleration"}):
        other = CONFIG.replace(change)
        assert learning_key(other, build_reference(other)) != key, change


def test_save_refuses_out_of_order(tmp_path: Path) -> None:
    result = run_trials(CONFIG, 0.05, 2)
    store = RunStore(tmp_path, CONFIG, build_reference(CONFIG))
    assert result.final is not None
    with pytest.raises(StoreError, match="out of order"):
        store.save(result.records[1], result.final)


def _simulate(args: list[str]) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "exo_ilc_ros.cli.main", "simulate", "--quiet",
                             "--mass-uncertainty", "0.1", *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env={**os.environ, "TQDM_DISABLE": "1"})


def test_kill_9_mid_run_then_resume_is_bit_identical(tmp_path: Path) -> None:
    trials = "60"
    store = tmp_path / "store"
    whole = _simulate(["--trials", trials, "--json", str(tmp_path / "whole.json")])
    victim = _simulate(["--trials", trials, "--store", str(store),
                        "--json", str(tmp_path / "killed.json")])
    deadline = time.monotonic() + 120
    completed = 0
    while time.monotonic() < deadline and victim.poll() is None:
        index = list(store.glob("*/index.json"))
        if index:
            try:
                completed = len(json.loads(index[0].read_text())["trials"])
            except ValueError:  # never: the index is replaced atomically
                raise
            if completed >= 5:
                break
        time.sleep(0.01)
    victim.send_signal(signal.SIGKILL)
    assert victim.wait(30) == -signal.SIGKILL, "the run ended before it could be killed"
    assert not (tmp_path / "killed.json").exists()
    resumed = _simulate(["--trials", trials, "--store", str(store), "--resume",
                         "--json", str(tmp_path / "resumed.json")])
    assert resumed.wait(300) == 0, resumed.stderr.read() if resumed.stderr else ""
    assert whole.wait(300) == 0, whole.stderr.read() if whole.stderr else ""
    a = json.loads((tmp_path / "whole.json").read_text())
    b = json.loads((tmp_path / "resumed.json").read_text())
    assert a == b  # floats written with repr: equal JSON means bit-identical tables
    assert len(b["runs"][0]["trials"]) == int(trials)
