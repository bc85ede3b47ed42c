"""``exo-ilc --help`` and ``exo-ilc CMD --help`` build the parser without loading the heavy
libraries a command needs only when it runs (optuna, matplotlib, scipy.signal, rclpy, numba and
its kernels): each sub-command imports them in its run path, so every command answers at once.
A run loads scipy.signal only when it filters (a Q-filter, the identification)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from exo_ilc_ros.cli.main import COMMANDS

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
