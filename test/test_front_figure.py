"""The front page's figure (docs/paper_figures.png) is `make demo`'s: its data
(docs/paper_figures.json, written with it by docs/paper_figure.py) equal the per-trial max |e| of
`exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15` now, the PNG was drawn from that data (its
Description names the data's sha256), and the captions say what it shows."""

from __future__ import annotations

import importlib.util
import json
import struct
from pathlib import Path
from types import ModuleType

import pytest

from exo_ilc_ros.cli.main import main as exo_ilc

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("paper_figure", DOCS / "paper_figure.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _png_text(path: Path) -> dict[str, str]:
    """The PNG's tEXt chunks (keyword: text)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, at = {}, 8
    while at < len(data):
        (length,) = struct.unpack(">I", data[at:at + 4])
        kind = data[at + 4:at + 8]
        if kind == b"tEXt":
            key, _, text = data[at + 8:at + 8 + length].partition(b"\0")
            out[key.decode("latin-1")] = text.decode("latin-1")
        at += 12 + length
    return out


def test_the_figures_data_are_make_demos_trials(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """`make demo`'s command with --json: every run's per-trial true max |e| equals the
    figure's data exactly (the same floats), and the PNG names the data's digest."""
    script = _script()
    shown = json.loads((DOCS / "paper_figures.json").read_text())
    assert shown["command"] == "exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15"
    out = tmp_path / "demo.json"
    assert exo_ilc([*shown["command"].split()[1:], "--json", str(out), "--quiet"]) == 0
    capsys.readouterr()
    demo = json.loads(out.read_text())
    assert shown["joint_names"] == demo["config"]["joint_names"]
    assert len(demo["runs"]) == len(shown["runs"]) == 3
    for ours, theirs in zip(shown["runs"], demo["runs"], strict=True):
        assert (ours["law"], ours["mass_uncertainty"], ours["error_bound"]) == \
            (theirs["law"], theirs["mass_uncertainty"], theirs["error_bound"])
        assert ours["true_max_abs_error"] == [t["true_max_abs_error"] for t in theirs["trials"]]
    description = _png_text(DOCS / "paper_figures.png").get("Description", "")
    assert description == "curves sha256 " + script.curves_digest(shown)


def test_the_captions_say_what_the_figure_shows() -> None:
    """README and the site's front page: `make demo`'s runs, its command, in-process, and
    where the figure and its data come from; no claim that the graph drew it."""
    for page in (ROOT / "README.md", DOCS / "index.md"):
        text = page.read_text()
        caption = text[text.index("![max |e|"):text.index("\n\n", text.index("\n\n(", text.index(
            "![max |e|")) + 2)]
        assert "make demo" in caption and "150 trials" in caption, page
        assert "exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15" in " ".join(caption.split())
        assert "in-process" in caption and "docs/paper_figure.py" in caption
        assert "docs/paper_figures.json" in caption
        assert "through the ROS 2 graph (the paper" not in caption
