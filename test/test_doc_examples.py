"""The docs say what is there (issue 36): every ```python block of README.md and docs/*.md runs as
written (in a scratch directory holding the checkout's shipped `config/` and `urdf/`, so an
example reads shipped files by their paths and makes whatever else it reads), and every path
(`core/arm/urdf_chain.py`, `config/arms/panda.yaml`, `docs/...`) and every dotted name
(`exo_ilc_ros.core.arm.dynamics`) named in the docs, the package's docstrings, the benches and
the docs' scripts exists.

A block that must not run says so on the line before its fence, with the reason:
``<!-- example: not run: REASON -->``."""

from __future__ import annotations

import contextlib
import importlib
import io
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
NOT_RUN = re.compile(r"<!-- example: not run: (\S.*\S) -->")
SHIPPED = ("config", "urdf")
"""What a scratch directory links from the checkout (an example's relative paths)."""


@dataclass
class Block:
    page: Path
    line: int
    code: str
    not_run: str | None

    @property
    def name(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def python_blocks() -> list[Block]:
    """Every ```python block of the pages, with the line of its fence."""
    blocks = []
    for page in PAGES:
        lines = page.read_text().splitlines()
        k = 0
        while k < len(lines):
            if lines[k].strip() == "```python":
                end = next(i for i in range(k + 1, len(lines)) if lines[i].strip() == "```")
                marker = NOT_RUN.search(lines[k - 1]) if k > 0 else None
                blocks.append(Block(page, k + 1, "\n".join(lines[k + 1:end]) + "\n",
                                    marker.group(1) if marker else None))
                k = end
            k += 1
    return blocks


BLOCKS = python_blocks()


def test_the_docs_have_python_examples() -> None:
    """The collection finds the pages' blocks (README's and python-api's among them), and a
    block left out says why."""
    names = {b.page.name for b in BLOCKS}
    assert {"README.md", "python-api.md", "your-arm-urdf.md"} <= names
    for block in BLOCKS:
        assert block.not_run is None or len(block.not_run) > 10, block.name


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.not_run is None],
                         ids=lambda b: b.name)
def test_python_block_runs_as_written(block: Block, tmp_path: Path,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    for name in SHIPPED:
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    code = compile(block.code, block.name, "exec")
    with contextlib.redirect_stdout(io.StringIO()):
        exec(code, {"__name__": "__doc_example__"})  # the docs' own code


PACKAGE_ROOTS = ("core", "cli", "nodes", "analysis", "bag", "orchestration", "wire")
"""A path that starts with one of these is under exo_ilc_ros/ (``core/arm/dynamics.py``)."""
CHECKOUT_ROOTS = ("exo_ilc_ros", "config", "docs", "test", "bench", "urdf", "launch")
ROOTS = "|".join(PACKAGE_ROOTS + CHECKOUT_ROOTS)
PATH = re.compile(rf"(?<![\w/.:~$-])((?:{ROOTS})/[\w./:-]*[\w/])")
DOTTED = re.compile(r"(?<![\w./])(exo_ilc_ros(?:\.\w+)+)")
SUFFIXES = (".py", ".yaml", ".yml", ".md", ".urdf", ".json", ".png", ".xml", ".html", ".mcap",
            ".txt", ".csv")


def _texts() -> list[Path]:
    """The docs, the package's sources (their docstrings), the benches and the docs' scripts."""
    return [*PAGES, *sorted((ROOT / "exo_ilc_ros").rglob("*.py")),
            *sorted((ROOT / "bench").glob("*.py")), *sorted((ROOT / "docs").glob("*.py"))]


def _path_exists(token: str) -> bool:
    """``token`` names a file or directory of the checkout: a path (``::test``, ``:line``
    after it allowed), or ``module/path.attribute`` (``core/arm/dynamics.metric_terms``)."""
    path = re.sub(r":\d+(-\d+)?$", "", token.split("::")[0])
    base = ROOT / "exo_ilc_ros" if path.split("/")[0] in PACKAGE_ROOTS else ROOT
    if (base / path).exists():
        return True
    last = path.rsplit("/", 1)[-1]
    if "." in last and not path.endswith(SUFFIXES):
        return (base / (path.split(".")[0] + ".py")).exists()
    return False


def _placeholder(token: str, after: str) -> bool:
    """``config/arms/<arm>.yaml``, ``config/scenarios/*.yaml``, ``NAME.yaml``: not a path."""
    return after in "<*{" or bool(re.search(r"/[A-Z][A-Z_]+(\.|/|$)", token)) or \
        token.startswith("docs/_build")


def _dotted_exists(name: str) -> bool:
    """``exo_ilc_ros.a.b.c``: the longest importable module, then attributes."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        try:
            target: object = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for part in parts[k:]:
            if not hasattr(target, part):
                return False
            target = getattr(target, part)
        return True
    return False


def stale_names() -> list[str]:
    """``file:line: name`` of every path and dotted name that does not exist."""
    stale = []
    for file in _texts():
        text = file.read_text()
        for match in PATH.finditer(text):
            token = match.group(1)
            if not _placeholder(token, text[match.end():match.end() + 1]) and \
                    not _path_exists(token):
                stale.append(f"{file.relative_to(ROOT)}:{text.count(chr(10), 0, match.start()) + 1}"
                             f": {token}")
        for match in DOTTED.finditer(text):
            name = match.group(1).rstrip(".")
            if not _dotted_exists(name):
                stale.append(f"{file.relative_to(ROOT)}:{text.count(chr(10), 0, match.start()) + 1}"
                             f": {name}")
    return stale


def test_every_named_path_and_module_exists() -> None:
    assert stale_names() == []


def test_a_stale_name_is_found(tmp_path: Path) -> None:
    """The checks see the names the issue found stale (moved modules), and accept the moved
    ones and placeholders."""
    assert not _path_exists("core/dynamics.py") and _path_exists("core/arm/dynamics.py")
    assert not _path_exists("core/dynamics.metric_terms")
    assert _path_exists("core/arm/dynamics.metric_terms")
    assert _path_exists("test/test_safety.py::test_x") and _path_exists("cli/main.py:34")
    assert not _dotted_exists("exo_ilc_ros.core.config")
    assert _dotted_exists("exo_ilc_ros.core.params.config.load_config")
    assert not _dotted_exists("exo_ilc_ros.core.params.config.no_such_name")
    assert _placeholder("config/scenarios/NAME.yaml", "")
    assert _placeholder("config/arms/", "<")
    text = "see `core/metrics.py` and :mod:`exo_ilc_ros.core.experiment`"
    assert [m.group(1) for m in PATH.finditer(text)] == ["core/metrics.py"]
    assert [m.group(1) for m in DOTTED.finditer(text)] == ["exo_ilc_ros.core.experiment"]
