"""Error types of the bag package, each naming the bag (or file) and what was wrong."""

from __future__ import annotations

from pathlib import Path

from ..core.errors import ExoIlcError


class BagError(ExoIlcError):
    """Base class of the bag errors: ``path`` is the bag or file, ``problem`` what was wrong."""

    def __init__(self, path: Path | str, problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class BagReadError(BagError):
    """A bag cannot be read or does not hold what the analysis needs."""


class BagWriteError(BagError):
    """A bag cannot be written (target exists, writer closed, unknown topic, ...)."""
