"""A trial left out of a bag as damaged (`exo-ilc analyze --skip-damaged`) is not known: it
counts neither within nor out of the bound, so the iterations to the bound are those of the run
(the issue saw "settled within" move from 4/5/5 to 14/14/14); a trial whose max |e| is NaN
because the plant diverged is still out of it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from exo_ilc_ros.bag import read_bag, write_run
from exo_ilc_ros.cli.main import main as exo_ilc
from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.convergence.bound import iterations_to_bound

TRIALS = 14


def test_unknown_rows_count_neither_way_and_nan_rows_are_out() -> None:
    """By hand, bound 0.005: trial 3 unknown -> within from trial 2; the same NaN row known
    (a diverged trial) -> out, settled from trial 4; the last trial unknown -> judged by the
    one before."""
    errors = np.array([[0.1], [0.001], [np.nan], [0.001]])
    known = np.array([True, True, False, True])
    its = iterations_to_bound(errors, 0.005, known)
    assert (its.first, its.settled) == ([2], [2])
    its = iterations_to_bound(errors, 0.005)
    assert (its.first, its.settled) == ([2], [4])
    its = iterations_to_bound(errors[:3], 0.005, known[:3])
    assert (its.first, its.settled) == ([2], [2])
    its = iterations_to_bound(np.array([[0.1], [0.002], [0.1]]), 0.005, np.array([1, 0, 1],
                                                                                  bool))
    assert (its.first, its.settled) == ([None], [None])
    its = iterations_to_bound(np.array([[0.001], [0.1], [0.001], [0.001]]), 0.005,
                              np.array([True, True, False, True]))
    assert (its.first, its.settled) == ([1], [4])


def test_a_trial_left_out_as_damaged_does_not_move_the_iterations(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = load_config().with_mass_uncertainty(0.1)  # settled within 4/5/5
    result = run_trials(config, 0.1, TRIALS)
    expected = result.iterations_to_bound()
    assert all(s is not None and s < TRIALS - 1 for s in expected.settled), expected
    bag = write_run(tmp_path / "bag", config, result)
    damaged = TRIALS - 1  # settled before it: a miss there would move "settled" to TRIALS
    file = sorted(bag.glob("*.mcap"), key=lambda f: int(f.stem.rsplit("_", 1)[1]))[damaged - 1]
    with open(file, "rb") as handle:
        (chunk,) = make_reader(handle).get_summary().chunk_indexes
    data = bytearray(file.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    file.write_bytes(bytes(data))
    run = read_bag(bag, skip_damaged=True)
    summary = run.summary()
    assert summary.extra["sources"][damaged - 1] == "missing"
    assert np.all(np.isnan(summary.max_abs_error[damaged - 1]))
    assert summary.iterations_to_bound() == expected
    out = tmp_path / "analysis.json"
    assert exo_ilc(["analyze", str(bag), "--skip-damaged", "--quiet", "--json", str(out)]) == 0
    capsys.readouterr()
    iterations = json.loads(out.read_text())["runs"][0]["iterations_to_bound"]
    assert iterations == {"first": expected.first, "settled": expected.settled}
    shutil.rmtree(bag)
