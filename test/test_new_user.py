"""What a new user hit (issue 25), in-process: the paper command, therapy metrics that mislead,
the growth check's NaN and false alarm, an implausible --mass-uncertainty, aborted runs that
exit 0, invisible live changes, credentials in messages, and the smaller points. Each test here
failed on the code before the fix (d51dd59)."""

from __future__ import annotations

import contextlib
import io
import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.figure import Figure

from exo_ilc_ros.analysis import figures
from exo_ilc_ros.analysis.loop import format_growth
from exo_ilc_ros.analysis.report import (
    format_iterations,
    format_long_run,
    format_run_events,
    format_trial_table,
)
from exo_ilc_ros.analysis.session_report import exercise_figure, exercise_run
from exo_ilc_ros.bag import read_bag, write_run
from exo_ilc_ros.cli.arguments import shown_command
from exo_ilc_ros.cli.main import main as exo_ilc
from exo_ilc_ros.cli.run import graph_domain
from exo_ilc_ros.core.convergence.growth import fit_growth
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.session.summary import RunSummary
from exo_ilc_ros.orchestration.graph import reruns

SHORT = '"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'


@pytest.fixture
def short(tmp_path: Path) -> Path:
    path = tmp_path / "short.yaml"
    path.write_text(SHORT)
    return path


# --- point 1: the paper command ---------------------------------------------------------------
def test_paper_in_process_writes_the_table_and_the_figure(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's command, as typed: exit 0, the table and the figure (it crashed on
    analyze's --skip-damaged, missing from the Namespace paper built by hand)."""
    monkeypatch.chdir(tmp_path)
    assert exo_ilc(["paper", "--in-process", "--trials", "20", "--plot", "f.png"]) == 0
    out = capsys.readouterr().out
    assert "Iterations to the bound" in out and (tmp_path / "f.png").stat().st_size > 10_000
    assert len(list((tmp_path / "bags").iterdir())) == 3


# --- point 3: therapy metrics -----------------------------------------------------------------
PLAN = ["shoulder_abduction", "elbow_flexion_extension", "reach_and_return"]
"""Not alphabetical: the report must keep this order."""


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Two in-process sessions of a passive virtual patient (3 trials of each exercise), their
    bags and what simulate printed."""
    root = tmp_path_factory.mktemp("therapy")
    out: dict[str, Any] = {"root": root}
    for k, extra in enumerate((["--new-patient"], []), start=1):
        bags = root / f"bags{k}"
        json_out = root / f"s{k}.json"
        with pytest.MonkeyPatch.context() as patch:
            patch.chdir(root)
            patch.setattr(sys, "argv", ["exo-ilc"])
            text = io.StringIO()
            with contextlib.redirect_stdout(text):
                code = exo_ilc(["simulate", "--patient", "p3", *extra, "--exercise", *PLAN,
                                "--trials", "3", "--bag-dir", str(bags), "--profiles",
                                str(root / "profiles"), "--json", str(json_out)])
        assert code == 0, text.getvalue()[-2000:]
        out[f"out{k}"] = text.getvalue()
        out[f"json{k}"] = json.loads(json_out.read_text())
        out[f"bags{k}"] = bags
    return out


def _therapy_metrics(document: dict[str, Any], exercise: str) -> list[dict[str, Any]]:
    run = next(r for r in document["runs"] if r["therapy"]["exercise"] == exercise)
    return list(run["therapy"]["metrics"])


def test_spasticity_of_a_joint_held_still_is_not_measurable(sessions: dict[str, Any]) -> None:
    """shoulder_abduction holds shoulder_flexion at 0: its B is null in the data and "not
    measurable" with the reason in the table, never a number (it was -6.48 N m s/rad)."""
    for metrics in _therapy_metrics(sessions["json1"], "shoulder_abduction"):
        assert metrics["spasticity"][0] is None
        assert metrics["spasticity"][1] is not None  # the moving joint keeps its number
        assert metrics["range_of_motion"][0] < np.radians(5.0)
    out = sessions["out1"]
    assert "not measurable" in out
    assert re.search(r"trial 1: B on shoulder_flexion not measurable: the joint barely moved "
                     r"\([0-9.]+ deg, needs 5 deg\)", out)


def test_passive_patients_share_is_never_negative(sessions: dict[str, Any]) -> None:
    """A passive virtual patient does no work: the share is 0 within its resolution, never a
    tiny negative number that the glossary reads as "worked against the robot"."""
    for exercise in PLAN:
        for metrics in _therapy_metrics(sessions["json1"], exercise):
            assert min(metrics["patient_share"]) >= 0.0, (exercise, metrics["patient_share"])
            assert metrics["patient_share_total"] >= 0.0
            assert 0.0 < metrics["patient_share_total_resolution"] < 0.05


def test_therapist_tables_are_in_degrees_and_per_cent(sessions: dict[str, Any]) -> None:
    out = sessions["out1"]
    assert "peak true |e| (deg)" in out and "patient's share of the work (%)" in out
    assert "(rad)" not in out.split("Therapy metrics")[1]


def test_therapy_tables_name_the_exercise_and_drop_the_paper_column(
        sessions: dict[str, Any]) -> None:
    """Point 7: per-trial table headings name the exercise; the paper's joint-1 numbers are
    for the paper's movement, not a therapy exercise."""
    out = sessions["out1"]
    for exercise in PLAN:
        assert f"{exercise}: sign d=0.05" in out
    assert "paper joint 1" not in out


@pytest.fixture(scope="module")
def report(sessions: dict[str, Any]) -> str:
    """The HTML report of session 1 (its bags as the shell's ``bags1/*`` lists them)."""
    first = sorted(str(p) for p in sessions["bags1"].iterdir())
    html = sessions["root"] / "r.html"
    assert exo_ilc(["report", *first, "--html", str(html), "--profiles",
                    str(sessions["root"] / "profiles")]) == 0
    return html.read_text()


def test_session_report_lists_exercises_in_session_order(report: str) -> None:
    assert re.findall(r"<h2>([a-z_]+)</h2>", report)[:3] == PLAN


def test_session_report_compares_with_earlier_sessions_only(report: str) -> None:
    """Session 1's report does not list session 2 (a later one) as an earlier session."""
    histories = report.split("Compared with earlier sessions")[1:]
    assert histories, "the report has no 'Compared with earlier sessions' part"
    for history in histories:
        table = history.split("</table>")[0]
        assert re.findall(r"<td class=l>v(\d+)", table) == ["1"]


def test_session_report_speaks_degrees(report: str) -> None:
    body = report.split("How to read this page")[0]
    assert " rad" not in re.sub(r"base64,[^']*'", "", body)
    assert "°" in body


def test_session_figure_share_in_per_cent_and_whole_trials(sessions: dict[str, Any]) -> None:
    """The share plot in % like the table; whole trials on the trial axis."""
    bag = sorted(sessions["bags1"].iterdir())[0]
    figure = exercise_figure(exercise_run(read_bag(bag)))
    assert "(%)" in figure.axes[3].get_ylabel()
    figure.canvas.draw()
    for ax in figure.axes[:4]:
        ticks = [t for t in ax.get_xticks() if 1 <= t <= 3]
        assert ticks and all(float(t).is_integer() for t in ticks), ticks


# --- point 4: the growth check ----------------------------------------------------------------
def test_growth_check_says_not_enough_data_never_nan(short: Path) -> None:
    config = load_config(short)
    run = RunSummary.from_result(run_trials(config, 0.05, 10))
    text = format_long_run([run], config["joint_names"])
    assert "nan" not in text.lower() and "not enough data" in text
    still = np.column_stack([np.linspace(1.0, 2.0, 30), np.zeros(30)])
    line = format_growth(fit_growth(still, 30), ["moving", "held"])
    assert "nan" not in line.lower() and "held joint still" in line


def test_a_learned_input_approaching_its_limit_is_not_growing() -> None:
    """The false GROWING of norm_optimal at 30 trials: over the fitted window its max |u_ff|
    still rises toward the limit (increments shrinking ~13 % a trial); geometric growth is
    still flagged."""
    k = np.arange(1, 31, dtype=float)
    approaching = np.column_stack([2.6 * (1.0 - 0.87 ** k), 0.37 + 0.0 * k])
    fit = fit_growth(approaching, 15)
    assert fit is not None and not fit.any_growing
    growing = np.column_stack([2.0 * 1.03 ** k, 1.0 + 0.0 * k])
    assert fit_growth(growing, 15).growing.tolist() == [True, False]  # type: ignore[union-attr]
    result = run_trials(load_config(), None, 30, law="norm_optimal")
    fit = fit_growth(result.max_abs_feedforward, 15)
    assert fit is not None and not fit.any_growing, fit


# --- point 5: implausible values and aborted runs ---------------------------------------------
def test_mass_uncertainty_as_a_percentage_is_refused_with_the_intent(
        short: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert exo_ilc(["simulate", "--config", str(short), "--trials", "2",
                    "--mass-uncertainty", "10"]) == 2
    err = capsys.readouterr().err
    assert "--mass-uncertainty" in err and "did you mean 0.1" in err


def test_a_run_whose_trials_abort_says_so_and_exits_4(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    tight = tmp_path / "tight.yaml"
    tight.write_text(SHORT + "    safety:\n      error_envelope: [0.01, 0.01, 0.01]\n")
    # two aborts: fewer than abort.max_consecutive (3), which would stop the run (exit 5)
    assert exo_ilc(["simulate", "--config", str(tight), "--trials", "2", "--quiet",
                    "--json", str(tmp_path / "r.json")]) == 4
    err = capsys.readouterr().err
    assert "ALL trials ABORTED by the error envelope" in err and "trials 1-2" in err
    run = json.loads((tmp_path / "r.json").read_text())["runs"][0]
    assert run["aborted_trials"] == [1, 2]


# --- point 6: live changes and re-run trials --------------------------------------------------
def test_live_changes_in_tables_json_and_analyze_json(
        short: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A law switched from trial 3 on: the per-trial table marks it, the iterations name both
    laws, and the JSON of the run and of `analyze --json` of its bag carry the change."""
    config = load_config(short)
    result = run_trials(config, 0.05, 5, changes={3: {"law": "linear"}})
    summary = RunSummary.from_result(result)
    assert summary.extra["live_changes"] == [{"trial": 3, "node": "ilc_supervisor",
                                              "parameter": "law", "value": "linear"}]
    table = format_trial_table([summary], config["joint_names"]).splitlines()
    row3 = next(line for line in table if line.startswith("    3 "))
    assert "linear from here" in row3
    assert "sign->linear" in format_iterations([summary], config["joint_names"])
    assert "live change from trial 3: ilc_supervisor law = \"linear\"" in \
        format_run_events([summary])
    bag = write_run(tmp_path / "bag", config, result)
    out = tmp_path / "a.json"
    assert exo_ilc(["analyze", str(bag), "--json", str(out)]) == 0
    assert "live change from trial 3" in capsys.readouterr().out
    run = json.loads(out.read_text())["runs"][0]
    assert run["live_changes"][0]["trial"] == 3 and run["laws"][1] == {"from_trial": 3,
                                                                        "law": "linear"}


def test_rerun_trials_are_reported() -> None:
    """A watchdog trip (the supervisor's ``aborted`` event with another reason than the error
    envelope) is a re-run trial in `run`'s summary and output."""
    events = [("start", {"trial": "1"}, 0.0),
              ("aborted", {"trial": "1", "reason": "watchdog"}, 1.0),
              ("start", {"trial": "1"}, 2.0),
              ("aborted", {"trial": "2", "reason": "error_envelope", "aborted_at": "5"}, 3.0)]
    again = reruns(events)
    assert again == [{"trial": 1, "reason": "watchdog"}]
    summary = RunSummary(0.05, "sign", 0.005, np.zeros((2, 3)), extra={"reruns": again})
    assert "trial 1 was run again (watchdog" in format_run_events([summary])


# --- point 8: credentials ---------------------------------------------------------------------
@pytest.mark.parametrize("argv", [
    ["tune", "--storage", "postgresql://u:secretpw@127.0.0.1:1/db", "--budget", "1",
     "--trials", "2"],
    ["study", "--dask", "tcp://u:secretpw@127.0.0.1:1", "--trials", "2", "--laws", "sign",
     "--scenarios", "ideal", "--mass-uncertainty", "0.1"],
], ids=["tune-storage", "study-dask"])
def test_no_password_is_ever_printed(argv: list[str], tmp_path: Path,
                                     monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    code = exo_ilc(argv)
    captured = capsys.readouterr()
    assert code == 2
    assert "secretpw" not in captured.out + captured.err
    assert "u:***@127.0.0.1" in captured.err


# --- point 9: the smaller ones ----------------------------------------------------------------
def test_an_exported_ros_domain_id_is_honoured(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert graph_domain(None) == 42 and graph_domain(7) == 7
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert graph_domain(None) is None  # then a free one is claimed


def test_simulate_takes_run_and_papers_bag_dir_flag(
        short: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert exo_ilc(["simulate", "--config", str(short), "--trials", "2", "--quiet",
                    "--bag-dir", str(tmp_path / "new")]) == 0
    assert exo_ilc(["simulate", "--config", str(short), "--trials", "2", "--quiet",
                    "--bag", str(tmp_path / "old")]) == 0
    assert "--bag is deprecated, use --bag-dir" in capsys.readouterr().err
    assert len(list((tmp_path / "new").iterdir())) == len(list((tmp_path / "old").iterdir())) == 1


def test_study_heatmap_title_fits_with_two_seeds(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    saved: dict[str, Figure] = {}
    real = figures.save

    def save(fig: Figure, path: Path | str) -> Path:
        saved["figure"] = fig
        return real(fig, path)

    monkeypatch.setattr(figures, "save", save)
    assert exo_ilc(["study", "--laws", "sign", "--scenarios", "ideal", "--mass-uncertainty",
                    "0.1", "--trials", "2", "--seeds", "2", "--workers", "1", "--figure",
                    str(tmp_path / "s.png")]) == 0
    fig = saved["figure"]
    fig.canvas.draw()
    assert fig.get_suptitle()
    box = fig._suptitle.get_window_extent()  # type: ignore[attr-defined]
    assert box.x0 >= 0 and box.x1 <= fig.bbox.x1, (box, fig.bbox)


def test_paper_help_prints_one_per_cent_sign(capsys: pytest.CaptureFixture[str]) -> None:
    for command in ("paper", "simulate", "run", "tune", "study", "compare", "analyze"):
        assert exo_ilc([command, "--help"]) == 0
        assert "%%" not in capsys.readouterr().out, command
    assert exo_ilc(["paper", "--help"]) == 0
    assert "15 % mass" in " ".join(capsys.readouterr().out.split())


def test_counts_are_singular_for_one(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert exo_ilc(["study", "--laws", "sign", "--scenarios", "ideal", "--mass-uncertainty",
                    "0.1", "--trials", "2", "--workers", "1"]) == 0
    err = capsys.readouterr().err
    assert "1 law x 1 scenario x 1 uncertainty x 1 seed = 1 cell of 2 trials" in err
    monkeypatch.chdir(tmp_path)
    short = tmp_path / "short.yaml"
    short.write_text(SHORT)
    assert exo_ilc(["simulate", "--config", str(short), "--patient", "p9", "--new-patient",
                    "--exercise", "paper_quintic", "--trials", "2", "--profiles", "prof"]) == 0
    capsys.readouterr()
    assert exo_ilc(["profiles", "--profiles", "prof", "list", "p9"]) == 0
    assert "1 version," in capsys.readouterr().out


def test_commands_shown_are_the_ones_that_work_here(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """In a checkout whose venv is not activated, exo-ilc is not on PATH: the commands we
    print (resume, tune's hint, param) say .venv/bin/exo-ilc."""
    script = tmp_path / ".venv" / "bin" / "exo-ilc"
    script.parent.mkdir(parents=True)
    script.write_text("#!/bin/sh\n")
    script.chmod(0o755)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    monkeypatch.setattr(sys, "argv", [str(script)])
    assert shown_command() == ".venv/bin/exo-ilc"
    monkeypatch.setenv("PATH", f"{script.parent}:/usr/bin:/bin")
    assert shown_command() == "exo-ilc"
