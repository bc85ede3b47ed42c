"""What a newcomer following the README hits (issue 18): `analyze bags/*` with a README and bags
of different lengths, figures whose legends hide nothing, cut joint names, `tune` overwriting the
shipped config/tuned.yaml, and `exo-ilc clean` for the bags and stores runs leave behind."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from matplotlib.figure import Figure

from exo_ilc_ros.analysis import figures
from exo_ilc_ros.analysis.report import format_iterations
from exo_ilc_ros.bag import read_bag, write_run
from exo_ilc_ros.cli.clean import parse_age
from exo_ilc_ros.cli.main import main as exo_ilc
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import run_trials

ROOT = Path(__file__).resolve().parents[1]
SHORT = {"trajectory.duration": 1.0}


@pytest.fixture(scope="module")
def config() -> Config:
    return load_config(overrides=SHORT)


@pytest.fixture(scope="module")
def bag_dir(tmp_path_factory: pytest.TempPathFactory, config: Config) -> Path:
    """Like the shipped bags/: a README.md and two bags of 5 and 3 trials (same law)."""
    root = tmp_path_factory.mktemp("bags")
    (root / "README.md").write_text("Recorded runs go here.\n")
    for name, delta, trials in (("run_a", 0.05, 5), ("run_b", 0.15, 3)):
        write_run(root / name, config, run_trials(config, delta, trials))
    return root


@pytest.fixture
def saved(monkeypatch: pytest.MonkeyPatch) -> dict[str, Figure]:
    """The figures `analyze` saves, by file name (and still written)."""
    out: dict[str, Figure] = {}
    real = figures.save

    def save(fig: Figure, path: Path | str) -> Path:
        out[Path(path).name] = fig
        return real(fig, path)

    monkeypatch.setattr(figures, "save", save)
    return out


def test_analyze_glob_skips_non_bags_and_labels_every_bag(
        tmp_path: Path, bag_dir: Path, saved: dict[str, Figure],
        capsys: pytest.CaptureFixture[str]) -> None:
    paths = sorted(str(p) for p in bag_dir.iterdir())  # what the shell makes of bags/*
    assert any(p.endswith("README.md") for p in paths)
    plot = tmp_path / "fig.png"
    code = exo_ilc(["analyze", *paths, "--plot", str(plot), "--trial", "4",
                    "--csv", str(tmp_path / "t.csv"), "--json", str(tmp_path / "t.json")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "skipping" in err and "README.md: not a rosbag2 bag" in err
    # run_b has 3 trials: no figure of trial 4 for it, said so, and the rest went on.
    assert "no tracking figure for run_b: it has no trial 4 (recorded: trials 1-3)" in err
    assert sorted(saved) == ["fig.png", "fig_run_a_trial4.png"]
    # Both tables name the bags.
    head = next(line for line in out.splitlines() if line.startswith("trial |"))
    assert "run_a" in head and "run_b" in head
    rows = [line for line in out.splitlines() if line.startswith(("run_a ", "run_b "))]
    assert len(rows) == 2
    # One legend entry per bag (plus the bound), all different, below the panels.
    fig = saved["fig.png"]
    assert all(ax.get_legend() is None for ax in fig.axes)
    (legend,) = fig.legends
    texts = [t.get_text() for t in legend.get_texts()]
    assert len(texts) == 3 and len(set(texts)) == 3
    assert texts[0].startswith("run_a") and texts[1].startswith("run_b")
    # The trial figure draws the bound in its error panels.
    trial_fig = saved["fig_run_a_trial4.png"]
    joints = 3
    for ax in trial_fig.axes[joints:2 * joints]:
        ys = sorted(float(line.get_ydata()[0]) for line in ax.get_lines()[1:])
        assert ys == [-0.005, 0.005]
    assert len(json.loads((tmp_path / "t.json").read_text())["runs"]) == 2


def test_analyze_checks_the_trial_before_writing_anything(
        tmp_path: Path, bag_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    outputs = [tmp_path / "fig.png", tmp_path / "t.csv", tmp_path / "t.json"]
    code = exo_ilc(["analyze", str(bag_dir / "run_a"), str(bag_dir / "run_b"),
                    "--plot", str(outputs[0]), "--trial", "9", "--csv", str(outputs[1]),
                    "--json", str(outputs[2])])
    err = capsys.readouterr().err
    assert code == 2
    assert "no bag has trial 9" in err and "run_a: trials 1-5; run_b: trials 1-3" in err
    assert not any(p.exists() for p in outputs)
    assert exo_ilc(["analyze", str(bag_dir / "README.md")]) == 2
    assert "no rosbag2 bag directory among the arguments" in capsys.readouterr().err


def test_headers_keep_whole_joint_names(bag_dir: Path) -> None:
    runs = [read_bag(bag_dir / "run_a").summary()]
    text = format_iterations(runs, ["shoulder_flexion", "shoulder_abduction", "elbow_flexion"])
    assert "shoulder_abduction" in text
    from exo_ilc_ros.analysis.tuning import RunScore, TuningResult
    from exo_ilc_ros.cli.tune import format_before_after

    score = RunScore(0.1, [3, 4, 5], [3, 4, 5], 5.0, 0.2, 0.2, 1e-3, 0.0)
    result = TuningResult("s", load_config(), 5.0, 5.0, [score], [score], 1)
    assert "shoulder_abduction" in format_before_after(
        result, ["shoulder_flexion", "shoulder_abduction", "elbow_flexion"])


def test_tune_never_overwrites_the_shipped_tuned_yaml(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Without --out the result goes under the git-ignored .exo-ilc/, named by the study."""
    shipped = ROOT / "config" / "tuned.yaml"
    before = hashlib.sha256(shipped.read_bytes()).hexdigest()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "config").mkdir()  # a checkout: config/tuned.yaml would be right here
    (tmp_path / "config" / "tuned.yaml").write_bytes(shipped.read_bytes())
    short = tmp_path / "short.yaml"
    short.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    assert exo_ilc(["tune", "--config", str(short), "--mass-uncertainty", "0.1", "--trials",
                    "3", "--budget", "1", "--jobs", "1", "--study-name", "my/study"]) == 0
    out = capsys.readouterr().out
    written = Path(".exo-ilc/tuned/my_study.yaml")
    assert written.is_file() and f"wrote {written}" in out
    assert f" compare --tuned {written}" in out  # after exo-ilc as typed here (issue 25)
    assert load_config(written)["law"] == "sign"
    assert (tmp_path / "config" / "tuned.yaml").read_bytes() == shipped.read_bytes()
    assert hashlib.sha256(shipped.read_bytes()).hexdigest() == before
    assert ".exo-ilc/" in (ROOT / ".gitignore").read_text().split()  # where it went: ignored


def _fake(path: Path, size: int, age_days: float, bag: bool = True) -> Path:
    path.mkdir(parents=True)
    name = "metadata.yaml" if bag else "store/index.json"
    (path / name).parent.mkdir(parents=True, exist_ok=True)
    (path / name).write_bytes(b"x" * size)
    stamp = time.time() - age_days * 86400
    for item in [*path.rglob("*"), path]:
        os.utime(item, (stamp, stamp))
    return path


def test_clean_lists_sizes_and_deletes_only_with_yes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bags, runs = tmp_path / "bags", tmp_path / ".exo-ilc" / "runs"
    bags.mkdir()
    (bags / "README.md").write_text("kept\n")
    old_bag = _fake(bags / "graph_sign_d0.1_old", 3 * 2**20, 10)
    mid_bag = _fake(bags / "graph_sign_d0.1_mid", 2 * 2**20, 3)
    new_bag = _fake(bags / "graph_sign_d0.1_new", 2**20, 0.5)
    live_bag = _fake(bags / "graph_sign_d0.1_live", 10, 0)  # a run still recording:
    (live_bag / ".splits").mkdir()  # the file of the trial it records is in .splits/
    old_store = _fake(runs / "20261101-120000-1", 2**20, 10, bag=False)
    new_store = _fake(runs / "20261130-120000-2", 2**20, 0.5, bag=False)
    args = ["clean", "--bag-dir", str(bags), "--runs-dir", str(runs)]

    assert exo_ilc(args) == 0  # lists only
    out = capsys.readouterr().out
    assert f"bags in {bags}: 4, 6.0 MiB" in out and f"stores in {runs}: 2, 2.0 MiB" in out
    assert "3.0 MiB" in out and "nothing selected" in out

    assert exo_ilc([*args, "--keep", "1"]) == 0  # dry run
    out = capsys.readouterr().out
    assert "would delete 4 entries, 7.0 MiB" in out and "--yes" in out
    assert all(p.exists() for p in (old_bag, mid_bag, new_bag, old_store, new_store))

    assert exo_ilc([*args, "--older-than", "2d", "--yes"]) == 0
    assert "deleted 3 entries, 6.0 MiB" in capsys.readouterr().out
    assert not old_bag.exists() and not mid_bag.exists() and not old_store.exists()
    assert new_bag.exists() and live_bag.exists() and new_store.exists()
    assert (bags / "README.md").exists()

    assert exo_ilc([*args, "--keep", "0", "--yes"]) == 0  # the live one stays
    assert "in use" in capsys.readouterr().out
    assert live_bag.exists() and not new_bag.exists() and not new_store.exists()

    assert parse_age("12h") == 43200 and parse_age("2") == 2 * 86400
    assert exo_ilc([*args, "--older-than", "soon"]) == 2
    assert "--older-than: 'soon' is not an age" in capsys.readouterr().err


def test_clean_calls_only_runs_still_going_in_use(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Written a moment ago: a finished bag (no .splits/) and the store of a run whose process
    has exited are deleted with --keep 0; a bag still recording and the store of a live process
    (this one) are in use and stay."""
    bags, runs = tmp_path / "bags", tmp_path / "runs"
    finished_bag = _fake(bags / "graph_sign_d0.1_finished", 10, 0)
    recording = _fake(bags / "graph_sign_d0.1_recording", 10, 0)
    (recording / ".splits").mkdir()
    exited = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                            capture_output=True, text=True, check=True)
    ended_store = _fake(runs / f"20261205-170000-{int(exited.stdout)}", 10, 0, bag=False)
    live_store = _fake(runs / f"20261205-170100-{os.getpid()}", 10, 0, bag=False)
    assert exo_ilc(["clean", "--bag-dir", str(bags), "--runs-dir", str(runs), "--keep", "0",
                    "--yes"]) == 0
    out = capsys.readouterr().out
    assert "deleted 2 entries" in out and out.count("in use") == 2
    assert not finished_bag.exists() and not ended_store.exists()
    assert recording.exists() and live_store.exists()
