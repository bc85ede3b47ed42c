"""The robustness study (issue 14): cells, their reduction to rows (hand-computed cases), the
same table from one process, a process pool and a Dask cluster, the command and its Ctrl-C."""

from __future__ import annotations

import ctypes
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import alive, children

from exo_ilc_ros.analysis.study import format_study_table, run_cells
from exo_ilc_ros.analysis.study_figure import study_figure
from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import config_dir, load_config, scenario_path
from exo_ilc_ros.core.programs.study import (
    CellResult,
    LawSpec,
    ScenarioSpec,
    resolve_law,
    resolve_scenario,
    run_cell,
    study_cells,
)
from exo_ilc_ros.core.programs.study_rows import study_rows
from exo_ilc_ros.core.session.learning_session import run_trials

ROOT = Path(__file__).resolve().parents[1]
IDEAL = ScenarioSpec("ideal", scenario_path("ideal"))


def cell(seed: int, errors: list[list[float]], feedforward: np.ndarray | None = None,
         aborted: list[int] | None = None, at_limit: list[int] | None = None,
         failure: str | None = None, law: str = "L") -> CellResult:
    """A cell result made by hand (two joints, 101 samples per trial)."""
    e = np.array(errors, dtype=float)
    ff = np.ones_like(e) if feedforward is None else feedforward
    return CellResult(law, "S", 0.1, seed, 0.005, 101, e, e * 2.0, ff, np.full_like(e, 3.0),
                      np.array(at_limit or [0] * len(e)), aborted or [], failure)


def test_rows_reduce_seeds_as_computed_by_hand() -> None:
    # seed 0: worst joint 0.1, 0.1, 0.004, 0.006, then 0.003 (joint 2 half of it)
    j1 = [0.1, 0.1, 0.004, 0.006] + [0.003] * 8
    seed0 = cell(0, [[x, x / 2] for x in j1], aborted=[2, 11], at_limit=[1] * 12)
    # seed 1: 0.05 at trial 1, then 0.002; joint 2's learned input grows by 5 % per trial
    j1 = [0.05] + [0.002] * 11
    ff = np.column_stack([np.ones(12), 1.05 ** np.arange(1, 13)])
    seed1 = cell(1, [[x, x / 2] for x in j1], feedforward=ff)
    seed1.max_abs_effort[7, 1] = 12.5
    [row] = study_rows([seed1, seed0], 12)
    assert (row.seeds, row.trials) == (2, 12)
    assert row.first == 3  # the later seed: seed 0 first within at trial 3
    assert row.settled == 5  # seed 0 leaves the bound again at trial 4
    # floors: seed 0 median of (0.003 x 8, 0.004, 0.006, 0.1, 0.1) = 0.003; seed 1: 0.002
    assert row.floor == pytest.approx(0.0025)
    assert (row.floor_low, row.floor_high) == pytest.approx((0.002, 0.003))
    assert row.floor_per_joint == pytest.approx((0.0025, 0.00125))
    assert row.growing_joints == (2,) and row.growing_seeds == 1
    assert row.max_growth_rate == pytest.approx(math.log(1.05))
    assert row.peak_effort == 12.5
    assert row.at_limit == pytest.approx(12 / (2 * 12 * 101))
    assert (row.aborts, row.late_aborts, row.last_abort) == (2, 1, 11)
    assert row.finite and not row.bounded and row.verdict == "growing"


def test_a_failed_or_short_run_is_not_bounded() -> None:
    fine = cell(0, [[0.001, 0.001]] * 12)
    [row] = study_rows([fine], 12)
    assert row.verdict == "bounded" and row.bounded and row.first == 1 and row.settled == 1
    stopped = cell(1, [[0.001, 0.001]] * 7, failure="after trial 7: the law produced a bad "
                   "feed-forward")
    [row] = study_rows([fine, stopped], 12)
    assert row.verdict == "failed" and not row.finite and not row.bounded
    assert row.failures == ("seed 1: after trial 7: the law produced a bad feed-forward",)
    assert math.isnan(row.floor)
    runaway = cell(5, [[0.001, 0.001]] * 12, aborted=[9])
    runaway.nonfinite = "non-finite state or effort from trial 9, sample 462, in the safe hold"
    [row] = study_rows([runaway], 12)
    assert row.verdict == "failed" and math.isnan(row.floor)
    assert row.failures == ("seed 5: non-finite state or effort from trial 9, sample 462, in "
                            "the safe hold",)
    assert "Runs that failed:" in format_study_table([row])
    late = cell(2, [[0.001, 0.001]] * 12, aborted=[11])
    [row] = study_rows([late], 12)
    assert row.verdict == "aborts" and not row.bounded
    early = cell(3, [[0.001, 0.001]] * 12, aborted=[10])  # the first 10 trials may abort
    assert study_rows([early], 12)[0].bounded
    never = cell(4, [[0.001, 0.009]] * 12)
    [row] = study_rows([never], 12)
    assert row.first is None and row.settled is None and row.floor == 0.009
    assert "9.00e-03*" in format_study_table([row])  # above the bound: marked


def test_laws_resolve_shipped_names_files_and_labels(tmp_path: Path) -> None:
    assert resolve_law("sign") == LawSpec("sign", None, {})
    assert resolve_law("linear").values == {"law": "linear"}
    assert resolve_law("norm_optimal").values == {"law": "norm_optimal"}
    assert resolve_law("robust").path == config_dir() / "robust.yaml"
    assert resolve_law("tuned").path == config_dir() / "tuned.yaml"
    mine = tmp_path / "slow.yaml"
    mine.write_text("ilc_supervisor:\n  ros__parameters:\n    law: linear\n")
    assert resolve_law(str(mine)) == LawSpec("slow", mine)
    assert resolve_law(f"careful={mine}") == LawSpec("careful", mine)
    assert resolve_law("mine=robust").values == {} and resolve_law("mine=robust").label == "mine"
    for bad in ("no_such_law", str(tmp_path / "missing.yaml")):
        with pytest.raises(ConfigError, match="--laws"):
            resolve_law(bad)
    with pytest.raises(ConfigError, match="given twice"):
        study_cells([resolve_law("sign"), resolve_law(f"sign={mine}")], [IDEAL], [0.1], [0], 5)
    assert resolve_scenario("ideal") == IDEAL


def test_a_cell_is_its_whole_configuration() -> None:
    [a, b] = study_cells([resolve_law("robust")], [IDEAL], [0.05, 0.15], [0], 7)
    shipped_robust = load_config(ROOT / "config" / "robust.yaml")
    assert (a.law, a.scenario, a.mass_uncertainty, b.mass_uncertainty) == \
        ("robust", "ideal", 0.05, 0.15)
    assert a.values["law"] == "linear" and a.values["q_filter.enabled"] is True
    assert a.values["q_filter.cutoff_hz"] == shipped_robust["q_filter.cutoff_hz"]
    assert (a.values["max_trials"], a.values["stop_when_settled"]) == (7, 0)
    assert a.values["mass_uncertainty"] == 0.05


def test_run_cell_tables_match_the_run_itself(tmp_path: Path) -> None:
    """run_cell's per-trial reduction against run_trials' own tables and a direct count of the
    samples at the effort limit (a law file with a low limit on joint 1 so some are)."""
    law = tmp_path / "weak.yaml"
    law.write_text('"/**":\n  ros__parameters:\n    control:\n'
                   "      effort_limit: [5.0, 40.0, 20.0]\n")
    [c] = study_cells([resolve_law(str(law))], [IDEAL], [0.1], [0], 6)
    result = run_cell(c)
    config = load_config(law, {"max_trials": 6, "mass_uncertainty": 0.1})
    run = run_trials(config)
    np.testing.assert_array_equal(result.true_max_abs_error, run.max_abs_errors)
    np.testing.assert_array_equal(result.max_abs_feedforward, run.max_abs_feedforward)
    np.testing.assert_array_equal(result.max_abs_effort, run.max_abs_effort)
    counted = [sum(1 for sample in r.effort if abs(sample[0]) >= 5.0) for r in run.records]
    assert result.samples_at_limit.tolist() == counted and sum(counted) > 0
    assert result.samples == run.records[0].effort.shape[0] == 501
    assert result.failure is None and result.aborted == run.aborted
    # under sensor noise the floor is the plant's true error, the measured one is kept beside it
    [c] = study_cells([resolve_law("robust")], [resolve_scenario("sensor")], [0.1], [3], 3)
    result = run_cell(c)
    run = run_trials(load_config(ROOT / "config" / "robust.yaml",
                                 {"max_trials": 3, "mass_uncertainty": 0.1, "patient.seed": 3},
                                 overlays=[scenario_path("sensor")]))
    np.testing.assert_array_equal(result.true_max_abs_error, run.true_max_abs_errors())
    np.testing.assert_array_equal(result.max_abs_error, run.max_abs_errors)
    assert not np.array_equal(result.true_max_abs_error, result.max_abs_error)


def _outcome(results: list[CellResult], trials: int) -> str:
    return json.dumps([r.to_json() for r in study_rows(results, trials)])


def test_pool_dask_and_one_process_give_the_same_table() -> None:
    from distributed import LocalCluster

    realistic = resolve_scenario("realistic")  # random draws per (seed, trial)
    cells = study_cells([resolve_law("sign"), resolve_law("robust")], [IDEAL, realistic], [0.1],
                        [0, 1], 12)
    serial = run_cells(cells, workers=1)
    pooled = run_cells(cells, workers=2)
    with LocalCluster(processes=False, n_workers=1, threads_per_worker=2,
                      dashboard_address=None) as cluster:
        done: list[str] = []
        clustered = run_cells(cells, dask=cluster.scheduler_address,
                              on_done=lambda c: done.append(c.label))
    assert sorted(done) == sorted(c.label for c in cells)
    for other in (pooled, clustered):
        assert [r.law for r in other] == [c.law for c in cells]
        assert all(a.same_as(b) for a, b in zip(serial, other, strict=True))
        assert _outcome(other, 12) == _outcome(serial, 12)
    assert format_study_table(study_rows(clustered, 12)) == \
        format_study_table(study_rows(serial, 12))
    # the seeds of a random patient differ, those of the ideal one do not
    by = {(r.law, r.scenario, r.seed): r for r in serial}
    assert not np.array_equal(by["robust", "realistic", 0].max_abs_error,
                              by["robust", "realistic", 1].max_abs_error)
    assert by["robust", "ideal", 0].same_as(
        CellResult(**{**vars(by["robust", "ideal", 1]), "seed": 0}))


def test_dask_refuses_another_version_and_an_unreachable_scheduler(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from distributed import LocalCluster

    from exo_ilc_ros.analysis import study

    cells = study_cells([resolve_law("sign")], [IDEAL], [0.1], [0], 2)
    with LocalCluster(processes=False, n_workers=1, threads_per_worker=1,
                      dashboard_address=None) as cluster:
        monkeypatch.setattr(study, "__version__", "0.0.0-client")  # the workers run 0.1.0
        with pytest.raises(study.ClusterError, match="same version on every worker"):
            run_cells(cells, dask=cluster.scheduler_address)
    monkeypatch.setattr(study, "CONNECT_TIMEOUT", "1s")
    with pytest.raises(study.ClusterError, match="cannot reach the Dask scheduler"):
        run_cells(cells, dask="tcp://127.0.0.1:9")


def test_study_command_table_json_and_figure(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    out, png = tmp_path / "study.json", tmp_path / "fig" / "study.png"
    code = main(["study", "--laws", "sign", "robust", "--scenarios", "ideal",
                 "--mass-uncertainty", "0.1", "--trials", "12", "--workers", "1",
                 "--json", str(out), "--figure", str(png)])
    assert code == 0
    text = capsys.readouterr().out
    assert re.search(r"^robust\s+ideal\s+10 %\s+\d+\s+\d+\s+\S+ +bounded\s", text, re.M), text
    data = json.loads(out.read_text())
    assert [r["law"] for r in data["rows"]] == ["sign", "robust"]
    assert data["study"]["trials"] == 12 and len(data["cells"]) == 2
    assert len(data["cells"][1]["true_max_abs_error"]) == 12
    assert png.is_file() and png.stat().st_size > 10_000


def test_study_command_refuses_workers_with_dask(capsys: pytest.CaptureFixture[str]) -> None:
    """(Bad values of each flag: test_cli_errors.py.)"""
    assert main(["study", "--workers", "2", "--dask", "tcp://localhost:1"]) == 2
    assert "--workers: applies to the local process pool" in capsys.readouterr().err


def test_figure_marks_growth_failure_and_aborts() -> None:
    ff = np.column_stack([np.ones(12), 1.05 ** np.arange(1, 13)])
    rows = study_rows([cell(0, [[0.001, 0.001]] * 12, law="good"),
                       cell(0, [[0.02, 0.001]] * 12, feedforward=ff, law="grows"),
                       cell(0, [[0.001, 0.001]] * 4, failure="after trial 4: x", law="fails"),
                       cell(0, [[0.001, 0.001]] * 12, aborted=[12], law="aborts")], 12)
    fig = study_figure(rows)
    ax = fig.axes[0]
    texts = [t.get_text() for t in ax.texts]
    assert texts == ["1.0e-3", "2.0e-2\ngrowing", "failed", "1.0e-3\n1 abort"]
    assert [p.get_hatch() for p in ax.patches] == ["///"]  # only the growing cell
    assert [t.get_text() for t in ax.get_yticklabels()] == ["good", "grows", "fails", "aborts"]


def _study_in_its_pool(tmp_path: Path) -> tuple[subprocess.Popen[str], list[str]]:
    """``exo-ilc study`` (2 workers, cells far longer than a test) in a session of its own,
    SIGKILLed if this process dies (no study left running after a killed test run), once its
    workers are inside their first cells; and its stderr so far."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}

    def child() -> None:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        ctypes.CDLL("libc.so.6").prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG

    process = subprocess.Popen(
        [sys.executable, "-m", "exo_ilc_ros.cli.main", "study", "--laws", "sign", "robust",
         "--scenarios", "ideal", "--trials", "3000", "--workers", "2"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
        start_new_session=True, preexec_fn=child)
    assert process.stderr is not None
    lines = []
    for line in process.stderr:  # the study has started its pool once the laws are listed
        lines.append(line)
        if "law robust" in line:
            break
    time.sleep(3.0)  # the workers are inside their first cells (3000 trials take much longer)
    return process, lines


def test_ctrl_c_stops_the_pool_without_worker_tracebacks(tmp_path: Path) -> None:
    """SIGINT to the whole process group (what Ctrl-C in a terminal does) while the pool runs:
    exit 130, one line, no traceback from the workers or the command."""
    process, lines = _study_in_its_pool(tmp_path)
    os.killpg(process.pid, signal.SIGINT)
    out, err = process.communicate(timeout=60)
    err = "".join(lines) + err
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert err.strip().endswith("exo-ilc study: interrupted")
    assert "Robustness study" not in out


def test_workers_die_with_a_killed_study(tmp_path: Path) -> None:
    """kill -9 of the study (not its group: what an OOM kill or a killed parent does) leaves no
    worker computing on: each gets SIGTERM from the kernel as its parent dies."""
    process, _ = _study_in_its_pool(tmp_path)
    workers = [pid for pid in children(process.pid)
               if "multiprocessing" in Path(f"/proc/{pid}/cmdline").read_text()]
    assert len(workers) >= 2, workers  # the pool's workers (and its resource tracker)
    process.kill()
    process.communicate(timeout=30)
    deadline = time.monotonic() + 20.0
    left = workers
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = [pid for pid in workers if alive(pid)]
    assert not left, f"workers {left} outlived their study"


def test_robust_config_survives_the_realistic_patient() -> None:
    """config/robust.yaml under every patient effect at once (`realistic`, 15 %), 300 trials:
    finite, no growth flag, no envelope abort after trial 10, and learning that works (the
    floor well under 0.02 rad; with its old 20 rad/s^2 bound on |u_ff| the learning was
    clipped at 0.36 rad, and the Q-filter at 5 Hz diverged under the first voluntary patient).
    The full 1000-trial, every-scenario check is the study of docs/study.md."""
    [c] = study_cells([resolve_law("robust")], [resolve_scenario("realistic")], [0.15], [0],
                      300)
    result = run_cell(c)
    [row] = study_rows([result], 300)
    assert row.finite and row.growing_seeds == 0 and row.late_aborts == 0, row
    assert row.bounded
    assert row.floor < 0.02, row.floor_per_joint
    assert np.all(result.max_abs_feedforward[-1] < 0.9 * np.asarray(c.values["feedforward_limit"]))
