"""Progress bars on stderr: tqdm's where a person watches them (a terminal), none elsewhere.

tqdm draws nothing when stderr is not a terminal (``disable=None``), but importing it costs
~70 ms (its command line and version modules) on every run; a command piped, scripted or run
by CI does not pay it.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO


class QuietBar:
    """What a command uses of a tqdm bar, drawing nothing; ``write`` still prints."""

    def __init__(self, total: int | None = None) -> None:
        self.total = total
        self.n = 0

    def __enter__(self) -> QuietBar:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def update(self, n: int = 1) -> None:
        """Count ``n`` more done."""
        self.n += n

    def set_postfix_str(self, text: str) -> None:
        """Nothing to draw."""

    def refresh(self) -> None:
        """Nothing to draw."""

    def write(self, text: str, file: TextIO | None = None) -> None:
        """Print a line, as ``tqdm.write`` does (stdout unless ``file``)."""
        print(text, file=sys.stdout if file is None else file)


def progress_bar(total: int | None, desc: str, unit: str) -> Any:
    """A context manager giving a bar on stderr: tqdm's on a terminal, else a :class:`QuietBar`
    (tqdm would draw nothing there either)."""
    if not sys.stderr.isatty():
        return QuietBar(total)
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=None)
