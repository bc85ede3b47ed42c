"""The README and the documentation site (docs/, Sphinx + MyST; `make docs` builds it with warnings
as errors, and `make test` runs that build): the README stays short, every section it used to
hold lives in a page, every relative link and anchor resolves, every page is in the site's
table of contents, and the CLI and API references are generated, not copied."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
README_LIMIT = 250

MOVED_SECTIONS: dict[str, tuple[str, str]] = {
    # the README's sections before the site (issue 24) -> the page holding it now, and a phrase
    # of its text that must be there (the section moved whole, not rewritten away)
    "Results against the paper": (
        "paper.md", "it amplifies last-bit differences"),
    "Convergence and the Q-filter": (
        "convergence.md", "`exo-ilc analyze-loop` says before a run whether it will"),
    "Norm-optimal ILC (model-based)": (
        "norm-optimal.md", "(Amann, Owens and Rogers' norm-optimal ILC)"),
    "Which law survives which patient": (
        "study.md", "Each law x scenario x uncertainty x seed is one *cell*"),
    "What the study found": (
        "study.md", "`config/robust.yaml` survives every shipped patient"),
    "Tuning the thresholds": (
        "tuning.md", "searches them with [Optuna](https://optuna.org)"),
    "The virtual patient": (
        "virtual-patient.md", "Modified Ashworth grades -> numbers"),
    "The ROS 2 graph": (
        "ros-graph.md", "[The wire contract](wire-contract.md)"),
    "Bags and offline analysis": (
        "bags.md", "Every `exo-ilc run` is recorded"),
    "Therapy sessions": (
        "therapy.md", "A clinic repeats the same movements over many sessions"),
    "Safety and reliability": (
        "safety.md", "Effort is bounded twice."),
    "The safe hold": (
        "safety.md", "Every fault above ends in the **safe hold**"),
    "Running on your own arm": (
        "your-arm.md", "Our simulator offers `reset` and `start` services"),
    "The contract your arm must meet": (
        "your-arm.md", "Before a person wears it."),
    "Hostile input, other publishers and real time": (
        "hostile-input.md", "Floods delay, they do not delete."),
    "Layout": (
        "architecture.md", "each imports only those below it (`test/test_layers.py`"),
    "The core in Python": (
        "python-api.md", "session = LearningSession(config)"),
    "Reading the paper": (
        "paper.md", "Model conventions: z up, gravity -z"),
    "Speed": (
        "performance.md", "`python -m bench.core_bench`: one 5 s trial"),
}
"""The README's own sections that stay in it (the two commands, the headline table of
``make demo``) are included into the site from the README itself (``{include}`` with markers)."""

RELIABILITY_SECTIONS = (
    "Safety in the loop", "Bad input gets a clear answer", "Nothing lost", "In the node graph",
    "Hostile input, other publishers and real time (issue 13)",
    "Trials without a reset (`protocol: homing`, any arm, MuJoCo)",
    "The robustness study (`exo-ilc study`)", "Not done (honest list)",
)

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~)")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")


def markdown_files() -> list[Path]:
    pages = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts)
    return [README, ROOT / "RELIABILITY.md", *pages]


def prose_lines(path: Path) -> list[str]:
    """The lines of a Markdown file outside fenced code blocks."""
    lines, fenced = [], False
    for line in path.read_text().splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(line)
    return lines


def slug(title: str) -> str:
    """A heading's anchor as GitHub and MyST (``myst_heading_anchors``) make it."""
    # markup out: code and strong/emphasis marks, but an underscore inside a word stays
    # (`control.min_stiffness` -> controlmin_stiffness, as MyST makes it)
    text = re.sub(r"`|\*{1,2}|(?<!\w)_{1,2}|_{1,2}(?!\w)", "", title.strip()).lower()
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    return {slug(m.group(2)) for line in prose_lines(path) if (m := HEADING.match(line))}


def headings(path: Path) -> list[str]:
    return [m.group(2) for line in prose_lines(path) if (m := HEADING.match(line))]


def test_readme_is_short() -> None:
    lines = README.read_text().count("\n")
    assert lines <= README_LIMIT, f"README.md has {lines} lines (at most {README_LIMIT})"
    text = README.read_text()
    for command in ("make demo   #", "make test   #", "exo-ilc simulate", "exo-ilc run",
                    "exo-ilc param set", "exo-ilc analyze"):  # the commands and the tour
        assert command in text, command
    assert "](docs/paper_figures.png)" in text  # its one figure


@pytest.mark.parametrize("section", sorted(MOVED_SECTIONS))
def test_every_section_of_the_old_readme_lives_in_a_page(section: str) -> None:
    page, phrase = MOVED_SECTIONS[section]
    path = DOCS / page
    assert path.is_file(), f"{section!r} should live in docs/{page}"
    text = path.read_text()
    assert phrase in text, f"docs/{page} lost the text of {section!r} ({phrase!r})"
    if section not in ("Layout", "Speed", "The core in Python"):  # renamed in their page
        assert section in headings(path), f"docs/{page} has no heading {section!r}"


def test_reliability_is_a_page_and_the_stub_points_there() -> None:
    page = DOCS / "reliability.md"
    assert set(RELIABILITY_SECTIONS) <= set(headings(page))
    assert "(docs/reliability.md)" in (ROOT / "RELIABILITY.md").read_text()
    assert (ROOT / "RELIABILITY.md").read_text().count("\n") <= 5


def test_every_relative_link_and_anchor_resolves() -> None:
    checked = 0
    for document in markdown_files():
        for line in prose_lines(document):
            for target in LINK.findall(line):
                if re.match(r"[a-z]+:", target):
                    continue
                file_part, _, fragment = target.partition("#")
                path = (document.parent / file_part).resolve() if file_part else document
                where = f"{document.relative_to(ROOT)}: link {target}"
                assert path.is_relative_to(ROOT) and path.exists(), f"{where} does not resolve"
                if fragment and path.suffix == ".md":
                    assert fragment in anchors(path), f"{where}: no heading with that anchor"
                checked += 1
    assert checked >= 40  # the README's table of pages alone has 18


def test_included_parts_of_the_readme_are_marked() -> None:
    """The site includes the README's intro, its two commands and the headline table of
    ``make demo`` between markers: each marker is in the README exactly once."""
    include = re.compile(r"```\{include\} (\S+)\n((?::[\w-]+: .*\n)*)```")
    readme = README.read_text()
    found = 0
    for page in DOCS.glob("*.md"):
        for target, options in include.findall(page.read_text()):
            assert (page.parent / target).resolve() == README
            for marker in re.findall(r":(?:start-after|end-before): (.*)", options):
                assert readme.count(marker) == 1, f"docs/{page.name}: marker {marker!r}"
                found += 1
    assert found >= 6
    table = readme.split("<!-- make-demo-table:start -->")[1]
    table = table.split("<!-- make-demo-table:end -->")[0]
    assert table.count("\n| ") >= 6 and "| 10 % |" in table


def test_every_page_is_in_the_table_of_contents() -> None:
    toctrees = re.findall(r"```\{toctree\}\n(.*?)```", (DOCS / "index.md").read_text(), re.S)
    listed = {line.strip() for tree in toctrees for line in tree.splitlines()
              if line.strip() and not line.startswith(":")}
    pages = {p.relative_to(DOCS).with_suffix("").as_posix() for p in DOCS.rglob("*.md")
             if not {"_build", "api"} & set(p.relative_to(DOCS).parts)} - {"index"}
    assert pages <= listed, f"pages in no toctree of docs/index.md: {sorted(pages - listed)}"
    assert listed <= pages, f"toctree entries without a page: {sorted(listed - pages)}"


def test_cli_and_api_references_are_generated() -> None:
    """The CLI page renders the parser ``exo-ilc`` runs, the API page autosummarises packages
    that exist: neither is a hand copy."""
    cli = (DOCS / "cli.md").read_text()
    assert re.search(r"```\{argparse\}\n:module: exo_ilc_docs\n:func: cli_parser\n", cli)
    extension = (DOCS / "_ext" / "exo_ilc_docs.py").read_text()
    assert "from exo_ilc_ros.cli.main import build_parser" in extension
    api = (DOCS / "python-api.md").read_text()
    block = api.split(".. autosummary::")[1].split("```")[0]
    assert ":recursive:" in block
    packages = [line.strip() for line in block.splitlines() if line.strip().startswith("exo_")]
    assert {"exo_ilc_ros.core", "exo_ilc_ros.bag", "exo_ilc_ros.analysis", "exo_ilc_ros.wire",
            "exo_ilc_ros.nodes"} <= set(packages)
    for package in packages:
        assert importlib.util.find_spec(package) is not None, package


def test_make_test_builds_the_docs_with_warnings_as_errors() -> None:
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^test: .*\bdocs\b", makefile, re.M)
    docs_rule = makefile.split("\ndocs:")[1].split("\n\n")[0]
    assert "sphinx-build -W" in docs_rule and " docs docs/_build/html" in docs_rule
