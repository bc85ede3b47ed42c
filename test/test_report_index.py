"""`exo-ilc report BAG... --html FILE` with the bags of two sessions: one page per session beside
FILE, and FILE itself the index linking them (before, FILE was never written)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from exo_ilc_ros.cli.main import main as exo_ilc


def test_two_sessions_give_two_pages_and_the_index_at_the_file_asked_for(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short = tmp_path / "short.yaml"
    short.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    common = ["--config", str(short), "--patient", "p1", "--profiles", str(tmp_path / "prof"),
              "--exercise", "paper_quintic", "--trials", "2", "--quiet"]
    bags = tmp_path / "bags"
    # two processes: a session is named by its start (to the second) and its process
    for extra in (["--new-patient", "--bag-dir", str(bags / "s1")], ["--bag-dir",
                                                                     str(bags / "s2")]):
        subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", "simulate", *common,
                        *extra], check=True, capture_output=True, cwd=tmp_path)
    out = tmp_path / "r.html"
    both = [str(p) for p in sorted(bags.glob("s*/*"))]
    assert exo_ilc(["report", *both, "--html", str(out), "--profiles",
                    str(tmp_path / "prof")]) == 0
    assert "the index of 2 sessions' pages" in capsys.readouterr().out
    index = out.read_text()
    links = re.findall(r'<a href="([^"]+)">', index)
    assert len(links) == 2 and all(link.startswith("r_p1_") for link in links)
    for link in links:
        page = (tmp_path / link).read_text()
        assert "paper_quintic" in page and "<html" in page
    assert "paper_quintic" in index
