"""The session report (exo-ilc report --html): self-contained, every number with its unit, the
safety events explained, the earlier sessions compared; rendered in headless Chromium as a
person would see it (screenshot not blank, no console message)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.analysis.session_report import ExerciseRun, render_session
from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.programs.metrics import TrialMetrics

ROOT = Path(__file__).resolve().parents[1]
UNIT = re.compile(r"^-?[0-9.]+(e[-+]?[0-9]+)? (deg|N m|deg/s\^2|%|N m s/deg)$"
                  r"|^-?[0-9.]+ \(SPARC, dimensionless\)$")
"""A therapist reads angles in degrees (issue 25); the data files keep rad."""


@pytest.fixture(scope="module")
def session_pages(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two sessions of patient p1 (two exercises, then one), bags and report of the second."""
    tmp = tmp_path_factory.mktemp("report")
    profiles, bags = tmp / "profiles", tmp / "bags"
    common = ["--config", str(ROOT / "config" / "robust.yaml"), "--patient", "p1",
              "--profiles", str(profiles), "--trials", "4", "--quiet"]
    assert main(["simulate", *common, "--new-patient", "--exercise", "paper_quintic",
                 "reach_and_return", "--bag", str(bags / "s1")]) == 0
    assert main(["simulate", *common, "--exercise", "paper_quintic", "reach_and_return",
                 "--bag", str(bags / "s2")]) == 0
    page = tmp / "report.html"
    second = sorted(str(p) for p in (bags / "s2").iterdir())
    assert main(["report", *second, "--html", str(page), "--profiles", str(profiles)]) == 0
    return page, tmp


def test_page_is_self_contained_and_names_every_unit(session_pages: tuple[Path, Path]) -> None:
    page, _ = session_pages
    text = page.read_text()
    assert "<script" not in text
    for target in re.findall(r"(?:src|href)=['\"]([^'\"]+)", text):
        assert target.startswith("data:image/png;base64,"), target  # nothing outside the page
    assert text.count("data:image/png;base64,") == 2  # one figure per exercise
    assert "paper_quintic" in text and "reach_and_return" in text
    assert "started from profile v1" in text and "v2 (this session)" in text
    # every number of the metric tables carries its unit
    tables = re.findall(r"<table><tr><th class=l>metric</th>.*?</table>", text, re.S)
    assert len(tables) == 2
    cells = [c for t in tables for c in re.findall(r"<td>([^<]*)</td>", t)]
    assert len(cells) > 40
    for cell in cells:
        for part in cell.split(" → "):
            assert UNIT.match(part), f"number without its unit: {cell!r}"


def test_safety_events_are_explained() -> None:
    metrics = [TrialMetrics(k, np.full(3, 0.01), np.full(3, 0.02), np.ones(3), np.ones(3),
                            np.zeros(3), 0.0, -1.5, np.zeros(3), k == 2) for k in (1, 2, 3)]
    run = ExerciseRun(Path("bag"), "p7", "reach_and_return", "s1", ["a", "b", "c"], metrics,
                      0.005, [0.2, 0.2, 0.2], "linear", True, 0.01, 10, aborts=[(2, 150)],
                      reruns=[(3, "watchdog"), (3, "lost")])
    text = render_session([run])
    assert "trial 2 stopped at t = 1.50 s" in text and "0.2 rad" in text
    assert "held the arm where it was" in text and "learned from up to where it stopped" in text
    assert "1 watchdog trip(s)" in text and "10 control periods (0.10 s)" in text
    assert "not something the patient did" in text and "trial 3 (lost)" in text
    assert "assist-as-needed" in text


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed (.ci/run "
                    "installs it as root: apt-get install chromium)")
def test_report_renders_in_headless_chromium(session_pages: tuple[Path, Path]) -> None:
    import matplotlib.image

    page, tmp = session_pages
    shot = tmp / "shot.png"
    env = dict(os.environ, HOME=str(tmp))  # chromium's profile and crash dirs go there
    done = subprocess.run(
        [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         f"--user-data-dir={tmp / 'chromium'}", "--enable-logging=stderr", "--v=0",
         f"--screenshot={shot}", "--window-size=1200,2000", page.as_uri()],
        capture_output=True, text=True, timeout=120, env=env, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    console = [line for line in done.stderr.splitlines() if ":CONSOLE" in line]
    assert not console, console  # the page logs nothing (no error, no warning)
    image = matplotlib.image.imread(shot)
    assert image.shape[0] >= 1000 and image.shape[1] >= 1000
    gray = image[..., :3].mean(axis=2)
    dark = np.count_nonzero(gray < 0.5) / gray.size
    assert dark > 0.01, f"screenshot nearly blank ({dark:.2%} dark pixels)"
    assert gray.std() > 0.05
    # colours: the figures' lines are drawn, not only black text on white
    rgb = image[..., :3]
    assert np.count_nonzero(rgb.max(axis=2) - rgb.min(axis=2) > 0.3) > 500


def test_a_seven_joint_arms_session_has_a_column_per_joint(tmp_path: Path) -> None:
    """Issue 27: a therapy session on a URDF arm (the Panda, 7 joints): the report's metric
    table has one column per joint, by the arm's joint names, every number with its unit."""
    from exo_ilc_ros.core.params.config import load_config

    arm = ROOT / "config" / "arms" / "panda.yaml"
    names = load_config(arm)["joint_names"]
    assert len(names) == 7
    common = ["--config", str(arm), "--patient", "p7", "--profiles", str(tmp_path / "profiles"),
              "--trials", "3", "--quiet", "--bag", str(tmp_path / "bags")]
    assert main(["simulate", *common, "--new-patient"]) == 0
    page = tmp_path / "report.html"
    bags = sorted(str(p) for p in (tmp_path / "bags").iterdir())
    assert main(["report", *bags, "--html", str(page)]) == 0
    text = page.read_text()
    (table,) = re.findall(r"<table><tr><th class=l>metric</th>.*?</table>", text, re.S)
    header = re.findall(r"<th>([^<]*)</th>", table.split("</tr>", 1)[0])
    assert [h for h in header if h in names] == list(names)
    cells = re.findall(r"<td>([^<]*)</td>", table)
    assert len(cells) >= 7 * 8
    for cell in cells:
        for part in cell.split(" → "):
            assert UNIT.match(part), f"number without its unit: {cell!r}"
