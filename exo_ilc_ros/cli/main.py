"""``exo-ilc``: the command line of exo_ilc_ros (what ros2cli, launch and rosbag2 would do here)."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import Any, TextIO

from ..core.errors import ExoIlcError
from ..core.params.redact import redact, secrets_in
from .arguments import hide_password

COMMANDS = ("simulate", "urdf", "layout", "tune", "compare", "run", "param", "analyze", "paper",
            "analyze_loop", "clean", "profiles", "report", "study", "ros2_control", "certify",
            "stretch_test")
"""Sub-command modules of this package; each has ``register(subparsers)`` setting ``func``."""


def build_parser() -> argparse.ArgumentParser:
    """The parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="exo-ilc", description="Iterative learning control for a rehabilitation "
        "exoskeleton arm (sgnPDD^2 / PD, computed torque).")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"{__package__}.{name}").register(sub)
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
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a refused value (2, message printed)
        return exc.code if isinstance(exc.code, int) else 2
    args.argv = list(sys.argv[1:] if argv is None else argv)  # to print commands that resume
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
