"""``exo-ilc``: the command line of exo_ilc_ros (what ros2cli, launch and rosbag2 would do here)."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import Any, TextIO

from ..core.errors import ExoIlcError
from ..core.params.redact import hide_password, redact, secrets_in

COMMANDS: dict[str, str] = {
    "simulate": "run the experiment in-process (no ROS)",
    "urdf": "write the arm's URDF from the config (a URDF arm: the chain the package uses of it)",
    "layout": "write the live view's layout for the config's arm (Foxglove, Lichtblick or "
              "PlotJuggler)",
    "tune": "auto-tune the sign law's thresholds and levels (Optuna)",
    "compare": "compare the paper's, the tuned sign law and the linear law",
    "run": "run the experiment through the ROS 2 node graph",
    "param": "get, set or list a running node's parameters",
    "analyze": "tables and figures from recorded bags (MCAP or sqlite3)",
    "paper": "the paper's experiment through the graph: 3 bags, 1 figure, 1 table",
    "analyze_loop": "trial-to-trial convergence factor per joint and frequency",
    "clean": "list the bags and stores of past runs with their sizes; delete old ones",
    "profiles": "list, show, export or roll back patients' learned profiles",
    "report": "the therapy session report (one HTML page per session)",
    "study": "robustness study: every law x patient scenario x uncertainty x seed",
    "ros2_control": "write the ros2_control controllers.yaml for the config's arm (a URDF arm's "
                    "joints: --config config/arms/...)",
    "certify": "a law's certificate over a population of patients (+ falsification)",
    "stretch_test": "stretch the person's elbow per MAS preset and velocity: resistance, reflex "
                    "stiffness, threshold angle",
}
"""Sub-command modules of this package (each has ``register(subparsers)`` setting ``func``; the
command is the module's name with ``-`` for ``_``) and the one-line help each registers: the
table ``exo-ilc --help`` lists without importing any of them (test_cli_startup.py checks that
it says what the modules register)."""

DESCRIPTION = ("Iterative learning control for a rehabilitation exoskeleton arm (sgnPDD^2 / PD, "
               "computed torque).")


def command_name(module: str) -> str:
    """The sub-command a module of :data:`COMMANDS` registers (``analyze_loop``:
    ``analyze-loop``)."""
    return module.replace("_", "-")


def chosen_command(argv: Sequence[str]) -> str | None:
    """The module of :data:`COMMANDS` whose sub-command ``argv`` names (the first word that is
    not an option: ``exo-ilc`` itself takes only ``-h``), or None."""
    first = next((word for word in argv if not word.startswith("-")), None)
    return next((module for module in COMMANDS if command_name(module) == first), None)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser of ``exo-ilc``. Without ``argv``, every sub-command registered (the CLI
    reference); with it, only the sub-command ``argv`` names is (its module imported), the others
    listed from :data:`COMMANDS` with their help, so ``exo-ilc --help`` and ``exo-ilc CMD ...``
    import no other command's module."""
    parser = argparse.ArgumentParser(prog="exo-ilc", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = None if argv is None else chosen_command(argv)
    for module, line in COMMANDS.items():
        if argv is None or module == chosen:
            importlib.import_module(f"{__package__}.{module}").register(sub)
        else:
            sub.add_parser(command_name(module), help=line)
    return parser


class RedactingStream:
    """A text stream that writes through another with every URL's password as ``***``
    (core/params/redact.py): what the command prints (its own lines, tqdm, a library's log or
    message) never shows a credential."""

    def __init__(self, stream: TextIO, secrets: Sequence[str] = ()) -> None:
        self.stream = stream
        self.secrets = list(secrets)

    def write(self, text: str) -> int:
        self.stream.write(redact(text, self.secrets))
        return len(text)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``exo-ilc``; returns the exit code (README: 0 done; 1 a bug, or a replay
    that differs; 2 a refused input; 3 the graph stopped; 4 trials aborted by the error
    envelope; 5 a run stopped by aborted trials in a row; 6 a failing certificate; 130
    Ctrl-C). Nothing it prints shows a password (:class:`RedactingStream`)."""
    out, err = sys.stdout, sys.stderr
    secrets = secrets_in(list(sys.argv[1:] if argv is None else argv))
    sys.stdout, sys.stderr = RedactingStream(out, secrets), RedactingStream(err, secrets)
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = out, err


def _main(argv: Sequence[str] | None = None) -> int:
    """:func:`main` inside the redacting streams."""
    words = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(words)
    try:
        args = parser.parse_args(words)
    except SystemExit as exc:  # argparse: --help (0) or a refused value (2, message printed)
        return exc.code if isinstance(exc.code, int) else 2
    args.argv = words  # to print commands that resume
    try:
        return int(args.func(args) or 0)
    except ExoIlcError as exc:
        print(f"exo-ilc {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"exo-ilc {args.command}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # a file named on the command line cannot be read or written
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"exo-ilc {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug, not the user's input: one line, the traceback on demand
        if os.environ.get("EXO_ILC_TRACEBACK"):
            raise
        if type(exc).__module__.startswith("sqlalchemy") and \
                getattr(args, "storage", None) is not None:  # the database of tune --storage
            reason = str(getattr(exc, "orig", None) or exc).splitlines()[0]
            print(f"exo-ilc {args.command}: error: argument --storage: cannot use the database "
                  f"{hide_password(args.storage)!r}: {reason}", file=sys.stderr)
            return 2
        print(f"exo-ilc {args.command}: internal error: {type(exc).__name__}: {exc}\n"
              "This is a bug in exo-ilc, not in what you typed; please report it with the command "
              "line (EXO_ILC_TRACEBACK=1 shows the traceback).", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
