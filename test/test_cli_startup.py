"""``exo-ilc --help`` and ``exo-ilc CMD --help`` build the parser without loading the heavy
libraries a command needs only when it runs (optuna, matplotlib, scipy.signal, rclpy, numba and
its kernels): each sub-command imports them in its run path, so every command answers at once.
A run loads scipy.signal only when it filters (a Q-filter, the identification)."""

from __future__ import annotations

import argparse
import importlib
import io
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import exo_ilc_ros.cli
from exo_ilc_ros.cli.main import COMMANDS, build_parser, chosen_command, command_name

HEAVY = ("optuna", "matplotlib", "scipy.signal", "rclpy", "numba")

PROBE = """
import contextlib, io, json, sys
command = sys.argv[1:]
sys.argv = ["exo-ilc", *command, "--help"]
from exo_ilc_ros.cli.main import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        code = main([*command, "--help"])
    except SystemExit as exc:
        code = exc.code
print(json.dumps({"code": code, "usage": out.getvalue().startswith("usage: exo-ilc"),
                  "loaded": [m for m in HEAVY if m in sys.modules]}))
""".replace("HEAVY", repr(HEAVY))


def _help_of(command: list[str]) -> dict:
    done = subprocess.run([sys.executable, "-c", PROBE, *command], capture_output=True,
                          text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("command", [[]] + [[name.replace("_", "-")] for name in COMMANDS],
                         ids=lambda c: " ".join(c) or "exo-ilc")
def test_help_loads_no_heavy_library(command: list[str]) -> None:
    answer = _help_of(command)
    assert answer["code"] == 0 and answer["usage"], answer  # the help was printed
    assert answer["loaded"] == [], f"exo-ilc {' '.join(command)} --help imported " \
        f"{answer['loaded']}"


TOP_PROBE = """
import contextlib, io, json, sys
from exo_ilc_ros.cli.main import main
with contextlib.redirect_stdout(io.StringIO()):
    code = main(["--help"])
print(json.dumps({"code": code, "loaded": sorted(m for m in sys.modules if m == "numpy"
                  or m.startswith("exo_ilc_ros.cli.") and m != "exo_ilc_ros.cli.main")}))
"""


def test_top_level_help_imports_no_command_and_no_numpy() -> None:
    """``exo-ilc --help`` lists the commands from the static table: it imports no sub-command's
    module and not numpy (0.3 s of a 0.4 s answer)."""
    done = subprocess.run([sys.executable, "-c", TOP_PROBE], capture_output=True, text=True,
                          check=True)
    assert json.loads(done.stdout.strip().splitlines()[-1]) == {"code": 0, "loaded": []}


def test_command_table_is_what_the_modules_register() -> None:
    """The static table cannot drift from the commands: every module of exo_ilc_ros.cli with a
    ``register`` is in it, and each registers exactly one command, named from the module, with
    the table's help line."""
    registering = {info.name for info in pkgutil.iter_modules(exo_ilc_ros.cli.__path__)
                   if hasattr(importlib.import_module(f"exo_ilc_ros.cli.{info.name}"),
                              "register")}
    assert registering == set(COMMANDS)
    for module, line in COMMANDS.items():
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(f"exo_ilc_ros.cli.{module}").register(sub)
        assert list(sub.choices) == [command_name(module)]
        assert [action.help for action in sub._choices_actions] == [line]


@pytest.mark.parametrize("module", list(COMMANDS))
def test_a_lazy_parser_parses_as_the_full_one(module: str) -> None:
    """The parser built for one command (the others listed from the table) prints the same
    top-level help as the full one, and that command's own help is the full parser's."""
    words = [command_name(module), "--help"]
    assert chosen_command(words) == module
    lazy, full = build_parser(words), build_parser()
    assert lazy.format_help() == full.format_help()

    def command_help(parser: argparse.ArgumentParser) -> str:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        return sub.choices[command_name(module)].format_help()

    assert command_help(lazy) == command_help(full)


def test_chosen_command_is_the_first_word() -> None:
    assert chosen_command(["--help"]) is None
    assert chosen_command([]) is None
    assert chosen_command(["simulate", "--config", "run"]) == "simulate"
    assert chosen_command(["-h", "analyze-loop"]) == "analyze_loop"
    assert chosen_command(["analyze_loop"]) is None  # the module's name is not a command


def test_probe_sees_a_heavy_import() -> None:
    """The probe itself can fail: a command that has run imports what it needs."""
    done = subprocess.run([sys.executable, "-c",
                           "import sys; from exo_ilc_ros.cli import tune; "
                           "from exo_ilc_ros.analysis import tuning; "
                           "print('optuna' in sys.modules)"],
                          capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "True"


RUN_PROBE = """
import contextlib, io, json, sys
from exo_ilc_ros.cli.main import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    code = main(["simulate", *sys.argv[1:], "--trials", "1", "--quiet"])
print(json.dumps({"code": code, "signal": "scipy.signal" in sys.modules}))
"""


@pytest.mark.parametrize("filters", [False, True], ids=["shipped", "q_filter"])
def test_a_run_loads_scipy_signal_only_when_it_filters(filters: bool, tmp_path: Path) -> None:
    """A one-trial simulate of the shipped config (no Q-filter, no identification) never
    imports scipy.signal (0.3-1 s of its start-up); with the Q-filter on it does."""
    short = tmp_path / "short.yaml"
    short.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 0.5\n'
                     + ("ilc_supervisor:\n  ros__parameters:\n    q_filter:\n      enabled: "
                        "true\n" if filters else ""))
    done = subprocess.run([sys.executable, "-c", RUN_PROBE, "--config", str(short)],
                          capture_output=True, text=True, check=True, cwd=tmp_path)
    answer = json.loads(done.stdout.strip().splitlines()[-1])
    assert answer == {"code": 0, "signal": filters}


PIPED_PROBE = """
import contextlib, io, json, sys
from exo_ilc_ros.cli.main import main
with contextlib.redirect_stdout(io.StringIO()):
    code = main(["simulate", *sys.argv[1:], "--trials", "2"])
print(json.dumps({"code": code, "tqdm": "tqdm" in sys.modules}))
"""


def test_a_piped_run_does_not_import_tqdm(tmp_path: Path) -> None:
    """With stderr not a terminal tqdm would draw nothing: a scripted or piped run does not pay
    its ~70 ms import (the one-trial simulate's start-up, issue 36)."""
    short = tmp_path / "short.yaml"
    short.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 0.5\n')
    done = subprocess.run([sys.executable, "-c", PIPED_PROBE, "--config", str(short)],
                          capture_output=True, text=True, check=True, cwd=tmp_path)
    assert json.loads(done.stdout.strip().splitlines()[-1]) == {"code": 0, "tqdm": False}


def test_progress_bar_is_tqdm_on_a_terminal_and_quiet_elsewhere(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from tqdm import tqdm

    from exo_ilc_ros.cli.progress import QuietBar, progress_bar

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(sys, "stderr", Terminal())
    with progress_bar(total=3, desc="d", unit="trial") as bar:
        assert isinstance(bar, tqdm)
        bar.update(2)
    assert "2/3" in sys.stderr.getvalue()  # drawn on the terminal
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    with progress_bar(total=3, desc="d", unit="trial") as bar:
        assert isinstance(bar, QuietBar)
        bar.update(2)
        bar.set_postfix_str("max|e| 1e-3")
        bar.write("a note", file=sys.stderr)
        bar.write("to stdout")
        assert bar.n == 2
    assert sys.stderr.getvalue() == "a note\n"  # notes still printed, no bar
    assert capsys.readouterr().out == "to stdout\n"
