"""Files an index lists by sha256 and rewrites in place (a profile version in progress, the
virtual patient's state with it: :mod:`.profiles`, :mod:`.patient_states`), kept readable
whatever moment a save is interrupted at.

A save writes the file, then the index naming its new sha256. Interrupted between the two
(kill -9, Ctrl-C, power loss), the file would no longer match the index and be refused as
corrupt: the trials it held would be lost. So before a save replaces the file the index lists,
it renames that file to ``<name>.previous``; a reader whose file does not match takes
``<name>.previous`` when that one does (the state of the last save the index completed).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from .files import _atomic

PREVIOUS = ".previous"


def previous_path(path: Path) -> Path:
    """Where the listed file is kept while a save replaces it."""
    return path.with_name(path.name + PREVIOUS)


def read_listed(path: Path, sha256: str) -> bytes | None:
    """The bytes of ``path`` if they match ``sha256``, else those of its ``.previous`` if they
    do (a save interrupted before its index), else None. OSError if neither can be read."""
    error: OSError | None = None
    for candidate in (path, previous_path(path)):
        try:
            blob = candidate.read_bytes()
        except OSError as exc:
            error = error or exc
            continue
        if hashlib.sha256(blob).hexdigest() == sha256:
            return blob
    if error is not None and not path.exists() and not previous_path(path).exists():
        raise error
    return None


def replace_keeping_listed(path: Path, blob: bytes, listed: str | None) -> None:
    """``blob`` to ``path`` atomically; the file it replaces kept as ``.previous`` first if it
    is the one the index lists (sha256 ``listed``), so that it stays readable until the index
    names the new one."""
    if listed is not None and path.is_file() and \
            hashlib.sha256(path.read_bytes()).hexdigest() == listed:
        os.replace(path, previous_path(path))
    with _atomic(path) as handle:
        handle.write(blob)
