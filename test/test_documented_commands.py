"""Every ``exo-ilc`` command that README.md and docs/*.md show runs to completion (issue 25).

The commands are read from the Markdown code blocks at test time (whatever the pages hold then),
in page order, and run in one scratch directory per page (a later command may read what an
earlier one wrote: ``analyze bags/*`` after ``run``), made short:

* ``--trials N`` becomes ``--trials 2`` (added where the command takes it), ``--budget`` 2,
  ``--seeds`` 2, ``--jobs``/``--workers`` 1, ``--lifted`` 50, ``--trial K`` at most 2;
* ``--config`` and every other ``.yaml`` a command reads: a shipped one (``config/robust.yaml``)
  is copied with a 1 s movement (and a person's 0.2 s of settling, not 1 s); one the page
  only names (``my_params.yaml``) is written as just that; a command that takes ``--config``
  and names none gets it (a ``--session`` command with the shipped exercises' session plans
  at most 2 trials an exercise: ``--session upper_limb`` runs 3 x 2 trials, not 3 x 20);
* ``<date>`` and other ``<placeholders>`` in a path match anything (``*``, the newest match;
  a path that matches nothing fails); a command with a placeholder that is no path
  (``--resume <session id>``) is only parsed; ``[optional]`` parts are left out;
* what needs something outside this machine (``postgresql://``, ``tcp://<host>``) or a running
  graph (``exo-ilc param``) is only parsed, with the page's values, and so is a ``run`` another
  test runs with the same flags and more checks (:data:`RUN_BY`);
* a live view (``run --live``) serves on a free port (``--live-port 0``, the page's port
  replaced or the flag added): the default 8765 (or the page's 9000) may be held by another
  test session on the machine, and the bridge then refuses to start.

A page with a graph command (``run``, ``paper``) runs all its commands in
:func:`test_documented_commands_run_with_the_graph`; every other page in
:func:`test_documented_in_process_commands_run`.

A command whose line ends in ``# exit N`` must exit N (a refused value shown on purpose); every
other must exit 0. Every command is also parsed as written
(:func:`test_every_documented_command_parses`), so a flag a page shows that the parser does not
know fails here in seconds.
"""

from __future__ import annotations

import contextlib
import glob
import io
import os
import re
import shlex
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml

from exo_ilc_ros.cli.main import build_parser
from exo_ilc_ros.cli.main import main as exo_ilc

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))])
SHORT_MOVEMENT = 1.0
"""Seconds of the movement in the scratch configs (101 samples a trial)."""
SHORT_SETTLE = 0.2
"""Simulated seconds a person with muscles hangs in the cuffs before trial 1 in the scratch
configs (``musculoskeletal.settle_time``, 1 s as shipped: the myoarm's 1 s of settling cost as
much as a trial), unless the config sets it."""
SMALL = {"--trials": "2", "--budget": "2", "--seeds": "2", "--jobs": "1", "--workers": "1",
         "--lifted": "50", "--trial": "2", "--population": "4", "--falsify": "2"}
"""Counts made small, and added where the command takes the flag but does not give it."""
ADDED = ("--trials", "--workers", "--jobs", "--budget")
"""Of those, the ones added to a command that does not give them."""
OUTPUTS = ("--out", "--config-out", "--json", "--csv", "--plot", "--html", "--figure")
"""Flags whose value is written, never made up beforehand."""
EXTERNAL = re.compile(r"postgresql://|mysql://|tcp://|<host>")
GRAPH_COMMANDS = ("run", "paper", "param")


@dataclass
class Command:
    """One documented command: where it is and its words after ``exo-ilc``."""

    page: Path
    line: int
    words: list[str]
    text: str = field(default="")
    expected: int = 0
    """The exit code the page says (a trailing ``# exit N``), else 0."""

    @property
    def name(self) -> str:
        return self.words[0] if self.words else ""

    def where(self) -> str:
        return f"{self.page.name}:{self.line}: {self.text}"


def _code_blocks(text: str) -> list[tuple[int, list[str]]]:
    """(first line number, lines) of every fenced code block."""
    blocks: list[tuple[int, list[str]]] = []
    current: list[str] = []
    start, fence = 0, ""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not fence and stripped.startswith(("```", "~~~")):
            fence, current, start = stripped[:3], [], number + 1
        elif fence and stripped.startswith(fence):
            blocks.append((start, current))
            fence = ""
        elif fence:
            current.append(line)
    return blocks


def documented_commands(page: Path) -> list[Command]:
    """The ``exo-ilc ...`` command lines of ``page``'s code blocks (continuations joined,
    comments and a leading ``$`` dropped)."""
    out = []
    for start, lines in _code_blocks(page.read_text()):
        k = 0
        while k < len(lines):
            number, line = start + k, lines[k]
            while line.rstrip().endswith("\\") and k + 1 < len(lines):
                k += 1
                line = line.rstrip()[:-1] + " " + lines[k].strip()
            k += 1
            text = line.strip().removeprefix("$ ")
            words = text.split(maxsplit=2)
            first = words[0] if words else ""
            if first != "exo-ilc" and not first.endswith("/exo-ilc"):
                continue
            if len(words) > 1 and words[1].endswith(":"):
                continue  # what the command printed ("exo-ilc simulate: ..."), not a command
            said = re.search(r"#\s*exits?\s+(\d+)\s*$", text)
            text = re.sub(r"\[[^\]]*\]", " ", text)  # [optional] parts left out
            try:
                words = shlex.split(text, comments=True)
            except ValueError as exc:
                pytest.fail(f"{page.name}:{number}: cannot split {text!r}: {exc}")
            out.append(Command(page, number, words[1:], " ".join(words),
                               int(said.group(1)) if said else 0))
    return out


ALL = [c for page in PAGES for c in documented_commands(page)]


def _subparser(name: str) -> Any:
    parser = build_parser()
    actions: list[Any] = [a for a in parser._actions
                          if a.__class__.__name__ == "_SubParsersAction"]
    return actions[0].choices[name]


def _takes(name: str, flag: str) -> bool:
    return flag in _subparser(name)._option_string_actions


def test_the_pages_show_commands() -> None:
    """The reader above finds the commands (else every test here would pass vacuously)."""
    assert len(ALL) >= 5, [str(p) for p in PAGES]
    assert {"simulate", "analyze"} <= {c.name for c in ALL}


@pytest.mark.parametrize("command", ALL, ids=[f"{c.page.name}:{c.line}" for c in ALL])
def test_every_documented_command_parses(command: Command, tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The command as the page writes it (its counts, its URLs; placeholders as ``x``, the
    files it reads made) is accepted by the parser; a command the page shows refused
    (``# exit 2``) exits with that code, with the message on stderr."""
    monkeypatch.chdir(tmp_path)
    words = [re.sub(r"<[^>]*>", "x", w) for w in command.words]
    _make_inputs(words, tmp_path)
    err = io.StringIO()
    if command.expected:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = exo_ilc(words)
        assert code == command.expected, f"{command.where()}: exits {code}, not " \
            f"{command.expected}:\n{err.getvalue()}"
        assert "error:" in err.getvalue(), err.getvalue()
        return
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            build_parser().parse_args(words)
    except SystemExit as exc:
        pytest.fail(f"{command.where()}: the parser refuses it (exit {exc.code}):\n"
                    f"{err.getvalue()}")


def _short_yaml(source: Path | None) -> str:
    """A ROS parameter YAML: ``source``'s parameters (or none) with a 1 s movement."""
    data = yaml.safe_load(source.read_text()) if source is not None else None
    data = data or {}
    params = data.setdefault("/**", {}).setdefault("ros__parameters", {})
    params.setdefault("trajectory", {})["duration"] = SHORT_MOVEMENT
    plant = data.setdefault("plant_simulator", {}).setdefault("ros__parameters", {})
    plant.setdefault("musculoskeletal", {}).setdefault("settle_time", SHORT_SETTLE)
    return yaml.safe_dump(data, sort_keys=False)


def _short_exercises() -> str:
    """The shipped exercises file with every session plan at most 2 trials an exercise (as
    ``--trials N`` becomes 2; the exercises themselves as shipped)."""
    data = yaml.safe_load((ROOT / "config" / "exercises" / "default.yaml").read_text())
    for plan in data["sessions"].values():
        for item in plan:
            item["trials"] = min(int(item["trials"]), int(SMALL["--trials"]))
    return yaml.safe_dump(data, sort_keys=False)


def _sessions_config(cwd: Path) -> str:
    """``short_sessions.yaml``, for a ``--session`` command: the 1 s movement and the short
    session plans (only there: ``exercise.file`` names this scratch directory, and a tuning
    study's journal records the config it was made for)."""
    (cwd / "exercises.yaml").write_text(_short_exercises())
    data = yaml.safe_load(_short_yaml(None))
    data["/**"]["ros__parameters"]["exercise"] = {"file": str(cwd / "exercises.yaml")}
    return yaml.safe_dump(data, sort_keys=False)


def _make_inputs(words: list[str], cwd: Path) -> None:
    """Write every ``.yaml`` the command reads and ``cwd`` lacks (module docstring)."""
    for k, word in enumerate(words):
        value = word.split("=", 1)[-1]  # LABEL=FILE
        if value.endswith((".yaml", ".yml")) and (k == 0 or words[k - 1] not in OUTPUTS) \
                and not (cwd / value).exists():
            shipped = ROOT / value
            (cwd / value).parent.mkdir(parents=True, exist_ok=True)
            (cwd / value).write_text(_short_yaml(shipped if shipped.is_file() else None))


def _inside(word: str, cwd: Path) -> str:
    """``word``, or an absolute path that names no existing file (a page's example of a
    shared journal, ``/shared/exo-ilc/tune.journal``) moved under ``cwd``: a test writes
    nothing outside its own directory, and nothing of one run is left for the next."""
    if not word.startswith("/") or Path(word).exists():
        return word
    moved = cwd / "absolute" / word.lstrip("/")
    moved.parent.mkdir(parents=True, exist_ok=True)
    return str(moved)


def _prepare(command: Command, cwd: Path, graph: bool) -> list[str] | None:
    """The command's words made short and runnable in ``cwd`` (module docstring); None when it
    can only be parsed, or (not ``graph``) reads what only a graph command makes."""
    words = list(command.words)
    if command.name == "param" or any(EXTERNAL.search(w) for w in words):
        return None
    out: list[str] = []
    for k, word in enumerate(words):
        before = words[k - 1] if k else ""
        if before in SMALL and word.isdigit():
            word = str(min(int(word), int(SMALL[before])))
        placeholder = "<" in word
        word = re.sub(r"<[^>]*>", "*", word)
        if any(c in word for c in "*?"):
            matches = sorted(glob.glob(word, root_dir=cwd))
            if not matches and (not graph or (placeholder and "/" not in word)):
                return None  # a graph run's bag (skipped here), or a value like <session id>
            if placeholder and matches:  # <date> names one: the newest
                matches = matches[-1:]
            out += matches or [word]
            continue
        out.append(_inside(word, cwd))
    _make_inputs(out, cwd)
    if "--live" in out:
        if "--live-port" in out:
            out[out.index("--live-port") + 1] = "0"
        else:
            out += ["--live-port", "0"]
    for flag in ADDED:
        if flag not in out and "--replay" not in out and _takes(command.name, flag):
            out += [flag, SMALL[flag]]
    if "--config" not in out and "--replay" not in out and _takes(command.name, "--config"):
        out += ["--config", "short_sessions.yaml" if "--session" in out else "short.yaml"]
    return out


def _written_flags(command: Command) -> frozenset[str]:
    """The flags of ``command`` as its page writes them."""
    return frozenset(w.split("=", 1)[0] for w in command.words if w.startswith("--"))


def test_the_commands_left_to_other_tests_are_run_there() -> None:
    """Every :data:`RUN_BY` entry names a test that exists and runs ``run`` with each of the
    flags (else the page's command would be run by no test), and some page shows it."""
    shown = {_written_flags(c) for c in ALL if c.name == "run"}
    for flags, where in RUN_BY.items():
        assert flags in shown, (sorted(flags), "no page shows it: drop the entry")
        file, name = where.split("::")
        source = (ROOT / "test" / file).read_text()
        assert f"\ndef {name}(" in source, where
        body = source.split(f"\ndef {name}(")[1].split("\ndef ")[0]
        assert '"run"' in body and all(f'"{flag}"' in body for flag in flags), (where, flags)


@dataclass
class Outcome:
    command: Command
    argv: list[str] | None
    code: int
    output: str


RUN_BY: dict[frozenset[str], str] = {
    frozenset({"--live", "--live-rate"}):
        "test_live.py::test_live_view_shows_what_the_bag_holds",
    frozenset({"--live", "--live-pace"}):
        "test_live.py::test_live_pace_changes_only_the_wall_time",
    frozenset({"--live", "--live-param"}):  # live-view.md (sample_reliability:=reliable there)
        "test_live.py::test_the_live_view_forwards_a_persons_cuffs_and_draws_the_person",
    frozenset({"--mass-uncertainty", "--trials", "--json"}):  # README.md, ros-graph.md
        "test_graph.py::test_run_reports_the_mass_uncertainty_it_ran",
    frozenset({"--config"}):  # ros-graph.md's ``run --config my.yaml``
        "test_graph.py::test_run_json_equals_simulate",
    frozenset({"--trials", "--store"}):  # safety.md: killed mid-run, ...
        "test_reliability.py::test_kill_9_the_supervisor_then_exo_ilc_run_resume",
    frozenset({"--trials", "--store", "--resume"}):  # ... then resumed
        "test_reliability.py::test_kill_9_the_supervisor_then_exo_ilc_run_resume",
    frozenset({"--plant", "--law", "--mass-uncertainty", "--trials"}):  # your-arm.md, MuJoCo
        "test_arm_graph.py::test_mujoco_with_homing_matches_simulate_and_survives_a_kill",
    frozenset({"--patient", "--exercise", "--trials"}):  # therapy.md: from the profile
        "test_therapy.py::test_graph_session_from_the_profile_equals_in_process",
    frozenset({"--scenario", "--trials"}):  # virtual-patient.md: a scenario through the graph
        "test_graph.py::test_urdf_arm_through_the_graph_equals_in_process",
}
"""Graph commands (``run`` with exactly these flags, as the page writes it) that another test
runs with these flags, checking its exit 0 and more: only parsed here (each graph run is
~10 s of the suite). :func:`test_the_commands_left_to_other_tests_are_run_there` checks that
the test named runs ``run`` with every one of the flags. A page whose graph commands are all
run elsewhere is an in-process page here."""

GRAPH_RUNS: set[tuple[str, ...]] = set()
"""The graph commands (as run) a page of this session already ran."""


def _run_page(page: Path, tmp: Path, graph: bool) -> list[Outcome]:
    """Run ``page``'s commands in order in ``tmp``: the in-process ones, and the graph ones
    when ``graph`` (a graph command with the same flags as one already run on the page is run
    once, and one an earlier page ran word for word is not run again: README.md's and
    ros-graph.md's ``run --mass-uncertainty 0.10 --trials 150 --json run.json``; a later
    command of the page that reads what it would have written then fails, it does not pass)."""
    (tmp / "short.yaml").write_text(_short_yaml(None))
    (tmp / "short_sessions.yaml").write_text(_sessions_config(tmp))
    outcomes, seen = [], set()
    old = Path.cwd()
    os.chdir(tmp)
    try:
        for command in documented_commands(page):
            argv = _prepare(command, tmp, graph)
            if argv is None:
                continue
            if command.name in GRAPH_COMMANDS and "--in-process" not in argv:
                if command.name == "run" and _written_flags(command) in RUN_BY:
                    continue
                flags = (command.name, frozenset(w for w in argv if w.startswith("--")))
                if not graph or flags in seen or tuple(argv) in GRAPH_RUNS:
                    continue
                seen.add(flags)
                GRAPH_RUNS.add(tuple(argv))
            began = time.perf_counter()
            # A real file, not a StringIO: the graph hands the nodes' output its descriptor.
            with tempfile.TemporaryFile("w+") as text:
                with contextlib.redirect_stdout(text), contextlib.redirect_stderr(text):
                    code = exo_ilc(argv)
                text.seek(0)
                output = text.read()
            if os.environ.get("EXO_ILC_TEST_TIMES"):
                print(f"{time.perf_counter() - began:6.1f} s  {command.where()}")
            outcomes.append(Outcome(command, argv, code, output))
    finally:
        os.chdir(old)
    return outcomes


CERTIFICATE_FAILED = 6
"""``certify``'s exit on a failing certificate: an answer, not an error (the commands run with
2 trials here, fewer than the certificate's criteria need, so every certificate fails)."""


def _answered(o: Outcome) -> bool:
    return o.code == o.command.expected or \
        (o.command.name == "certify" and o.command.expected == 0 and o.code == CERTIFICATE_FAILED)


def _failures(outcomes: list[Outcome]) -> str:
    return "\n\n".join(f"{o.command.where()}\n  ran: exo-ilc {shlex.join(o.argv or [])}\n  "
                       f"exit {o.code} (the page says {o.command.expected}):\n{o.output[-1500:]}"
                       for o in outcomes if not _answered(o))


def _has_graph_commands(page: Path) -> bool:
    """``page`` shows a graph command that no other test runs (:data:`RUN_BY`)."""
    return any(c.name == "paper" or (c.name == "run" and _written_flags(c) not in RUN_BY)
               for c in documented_commands(page) if "--in-process" not in c.words)


GRAPH_PAGES = [p for p in PAGES if _has_graph_commands(p)]
"""Pages whose commands all run in the graph test, in page order: the in-process ones too (a
superset of what the in-process test runs of them: that test also leaves out what reads a
graph run's bag), so they are not run a second time in-process (~1 min of the suite)."""
IN_PROCESS_PAGES = [p for p in PAGES if not _has_graph_commands(p)]


@pytest.mark.parametrize("page", IN_PROCESS_PAGES, ids=[p.name for p in IN_PROCESS_PAGES])
def test_documented_in_process_commands_run(page: Path, tmp_path: Path) -> None:
    """Every in-process command of ``page`` (simulate, analyze, tune, study, paper
    --in-process, profiles, report, clean, ...) exits 0 (the pages with graph commands: the
    graph test below)."""
    outcomes = _run_page(page, tmp_path, graph=False)
    assert not _failures(outcomes), _failures(outcomes)


@pytest.mark.graph
@pytest.mark.parametrize("page", GRAPH_PAGES, ids=[p.name for p in GRAPH_PAGES])
def test_documented_commands_run_with_the_graph(page: Path, tmp_path: Path) -> None:
    """All of ``page``'s commands in order, the in-process ones and the graph ones (``run``,
    ``paper``: real DDS, 2 trials of 1 s), so ``analyze bags/graph_*`` reads what ``run``
    recorded."""
    outcomes = _run_page(page, tmp_path, graph=True)
    assert any(o.command.name in ("run", "paper") for o in outcomes)
    assert not _failures(outcomes), _failures(outcomes)
