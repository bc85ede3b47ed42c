"""The in-process experiment: reference, trial loop, convergence of the laws, the CLI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core import Experiment, QuinticTrajectory, load_config, run_trials

ROOT = Path(__file__).resolve().parents[1]


def test_quintic_reference_meets_eq14() -> None:
    goal = [np.pi / 2, np.pi / 4, np.pi / 6]
    traj = QuinticTrajectory.rest_to_rest([0.0, 0.0, 0.0], goal, 5.0)
    q, qd, qdd = traj.evaluate(np.array([0.0, 2.5, 5.0]))
    np.testing.assert_allclose(q[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(q[1], np.array(goal) / 2, atol=1e-14)  # symmetric profile
    np.testing.assert_allclose(q[2], goal, atol=1e-14)
    np.testing.assert_allclose(qd[[0, 2]], 0.0, atol=1e-14)
    np.testing.assert_allclose(qdd[[0, 2]], 0.0, atol=1e-13)
    # the classic rest-to-rest quintic: q = q_f (10 s^3 - 15 s^4 + 6 s^5), s = t / T
    np.testing.assert_allclose(traj.coefficients[3:, 0] * np.array([5.0**3, 5.0**4, 5.0**5]),
                               np.array([10.0, -15.0, 6.0]) * goal[0], rtol=1e-12)


def test_reference_has_n_plus_one_samples() -> None:
    ex = Experiment(load_config())
    assert ex.reference.samples == 501
    assert ex.substeps == 10
    assert ex.reference.time[-1] == pytest.approx(5.0)


def test_trial_starts_at_the_reference_and_is_deterministic() -> None:
    ex = Experiment(load_config().with_mass_uncertainty(0.1))
    ff = np.zeros_like(ex.reference.position)
    a = ex.run_trial(ff, 1)
    b = ex.run_trial(ff, 1)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.position[0], ex.reference.position[0])
    np.testing.assert_allclose(a.control_input, ff + np.array([16.0, 10.0, 10.0]) * a.error
                               + np.array([8.0, 5.0, 7.0]) * a.error_velocity, atol=1e-12)
    with pytest.raises(ValueError, match="shape"):
        ex.run_trial(ff[:-1], 1)


def test_effort_limit_clamps_the_command() -> None:
    config = load_config(overrides={"control.effort_limit": [1.0, 1.0, 1.0]})
    record = Experiment(config.with_mass_uncertainty(0.1)).run_trial(np.zeros((501, 3)), 1)
    assert np.abs(record.effort).max() == pytest.approx(1.0)


@pytest.mark.parametrize("delta", [0.05, 0.10, 0.15])
def test_linear_law_reaches_the_bound_within_15_trials(delta: float) -> None:
    result = run_trials(load_config(), delta, trials=15, law="linear")
    its = result.iterations_to_bound()
    assert all(s is not None and s <= 15 for s in its.settled), its
    assert result.max_abs_errors[-1].max() < 0.005
    assert result.max_abs_errors[0].max() > 0.05  # it had something to learn


def test_sign_law_learns_and_reports_levels() -> None:
    result = run_trials(load_config(), 0.10, trials=6, law="sign")
    first, last = result.records[0], result.records[-1]
    assert first.levels is None
    assert last.levels is not None and last.levels.shape == (3, 3)
    # trial 2's M comes from |s e| of trial 1 through eq (22), written out here
    sums = np.abs(first.error.sum(axis=0))
    table = [(1.5, 20.0, 0.001, 0.03, 0.9), (2.0, 15.0, 0.001, 0.05, 0.5),
             (1.0, 15.0, 0.001, 0.05, 0.1)]
    expected = [hi if s > s2 else mid if s > s1 else lo
                for s, (s1, s2, lo, mid, hi) in zip(sums, table, strict=True)]
    assert sums[0] > 20.0  # joint 1 starts far off: the high step
    np.testing.assert_array_equal(result.records[1].levels[0], expected)
    assert result.max_abs_errors[-1].max() < 0.1 * result.max_abs_errors[0].max()


def test_cli_simulate_writes_the_json(tmp_path: Path) -> None:
    out = tmp_path / "run.json"
    exe = Path(sys.executable).with_name("exo-ilc")
    proc = subprocess.run([str(exe), "simulate", "--trials", "3", "--mass-uncertainty", "0.05",
                           "0.1", "--json", str(out)], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONUNBUFFERED": "1"}, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "Iterations to the bound" in proc.stdout
    document = json.loads(out.read_text())
    assert document["config"]["mass_uncertainty"] == 0.05
    runs = document["runs"]
    assert [r["mass_uncertainty"] for r in runs] == [0.05, 0.1]
    assert [t["trial"] for t in runs[0]["trials"]] == [1, 2, 3]
    assert len(runs[0]["trials"][0]["max_abs_error"]) == 3
    assert set(runs[0]["iterations_to_bound"]) == {"first", "settled"}
    expected = run_trials(load_config(), 0.1, trials=3).max_abs_errors
    np.testing.assert_array_equal([t["max_abs_error"] for t in runs[1]["trials"]], expected)


def test_cli_rejects_a_bad_config_with_the_key(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("ilc_supervisor:\n  ros__parameters:\n    error_bound: -1.0\n")
    exe = Path(sys.executable).with_name("exo-ilc")
    proc = subprocess.run([str(exe), "simulate", "--config", str(bad), "--trials", "1"],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2
    assert "error_bound" in proc.stderr and "> 0" in proc.stderr


def test_every_kernel_module_keys_the_numba_cache() -> None:
    """A compiled kernel that calls one of another module is cached stale unless every module
    with kernels is hashed into the cache directory (``core/_numba_cache.py``)."""
    from exo_ilc_ros.core import _numba_cache

    core = Path(_numba_cache.__file__).parent
    with_kernels = {p.relative_to(core).as_posix() for p in core.rglob("*.py")
                    if "@njit" in p.read_text()}
    assert with_kernels == set(_numba_cache.KERNEL_MODULES)
