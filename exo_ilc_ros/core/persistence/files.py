"""Files that are never seen half-written: atomic replacement (write to a temporary file in the
same directory, fsync, rename) and advisory directory locks."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

LOCK = ".lock"


@contextlib.contextmanager
def _atomic(path: Path) -> Iterator[IO[bytes]]:
    """Write ``path`` atomically: temp file in the same directory, fsync, rename, fsync dir."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def write_json_atomic(path: Path, document: Any) -> None:
    """``document`` as JSON to ``path``, atomically."""
    with _atomic(path) as handle:
        handle.write((json.dumps(document, indent=1, sort_keys=True) + "\n").encode())


@contextlib.contextmanager
def locked(directory: Path, shared: bool = False) -> Iterator[None]:
    """An exclusive ``flock`` of ``directory``/.lock (created, never deleted) for one
    read-change-write of the index and a version file; released when the block ends, or when
    the process dies. ``shared``: a reader's lock (index and file read as one state); without
    a lock file (no session has written here since locking existed) it reads unlocked."""
    if shared:
        try:
            fd = os.open(directory / LOCK, os.O_RDONLY)
        except FileNotFoundError:
            yield
            return
    else:
        fd = os.open(directory / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def write_bytes_atomic(path: Path | str, blob: bytes) -> None:
    """``blob`` to ``path``, atomically (as the store writes, :mod:`.store`)."""
    with _atomic(Path(path)) as handle:
        handle.write(blob)
