"""The site's own Sphinx extension: plain-text maths in docstrings and in ``exo-ilc``'s help.

The docstrings and the CLI's help write absolute values as ``|e|`` (``max |e|``, ``|F| > 1``);
reStructuredText would read ``|e|`` as a substitution reference and fail the build.
:func:`escape_pipes` escapes them in every docstring autodoc renders, and :func:`cli_parser`
gives sphinx-argparse ``exo-ilc``'s own parser (``exo_ilc_ros.cli.main.build_parser``) with the
same escaping in its help texts."""

from __future__ import annotations

import argparse
import re
from typing import Any

from exo_ilc_ros.cli.main import build_parser

_LITERAL_START = re.compile(r"(::\s*$)|(^\s*\.\.\s+[\w:-]+::)")


def escape_pipes(app: Any, what: str, name: str, obj: Any, options: Any,
                 lines: list[str]) -> None:
    """Read ``|e|`` in a docstring as an absolute value, not a substitution reference.

    The docstrings write plain-text maths (``max |e|``, ``|F| > 1``); reStructuredText would take
    ``|e|`` for a substitution and fail the build. The bars are escaped outside inline literals
    and literal blocks (a paragraph ending in ``::`` or a directive, and what is indented under
    it), where a backslash would show."""
    literal_indent: int | None = None
    for index, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None:
            if not line.strip() or indent > literal_indent:
                continue
            literal_indent = None
        if _LITERAL_START.search(line):
            literal_indent = indent
        lines[index] = escape_text(line)


def escape_text(text: str) -> str:
    """``text`` with every ``|`` outside ``inline literals`` escaped."""
    parts = text.split("``")
    for part in range(0, len(parts), 2):  # even parts lie outside ``inline literals``
        parts[part] = re.sub(r"(?<!\\)\|", r"\\|", parts[part])
    return "``".join(parts)


def _escape_parser(parser: argparse.ArgumentParser) -> None:
    for attribute in ("description", "epilog"):
        value = getattr(parser, attribute)
        if isinstance(value, str):
            setattr(parser, attribute, escape_text(value))
    for action in parser._actions:
        if isinstance(action.help, str):
            action.help = escape_text(action.help)
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                if isinstance(choice.help, str):
                    choice.help = escape_text(choice.help)
            for subparser in action.choices.values():
                _escape_parser(subparser)


def cli_parser() -> argparse.ArgumentParser:
    """``exo-ilc``'s parser, as the command builds it, its help texts escaped for rendering."""
    parser = build_parser()
    _escape_parser(parser)
    return parser


def setup(app: Any) -> dict[str, Any]:
    app.connect("autodoc-process-docstring", escape_pipes)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
