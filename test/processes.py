"""Test helpers for the processes a test starts: their children (the graph's node processes,
a study's pool workers), whether a process still runs, and SIGKILL of one named node."""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path


def children(pid: int) -> list[int]:
    """The child processes of ``pid`` (none once it is gone)."""
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(x) for x in path.read_text().split()] if path.exists() else []


def alive(pid: int) -> bool:
    """``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, IndexError):
        return False
    return state != "Z"


def sigkill_child(process: subprocess.Popen[str], name: str) -> str:
    """SIGKILL the one child of ``process`` (``exo-ilc run``) whose command line names
    ``name`` (a node); then ``process``'s stderr to its end."""
    pids = [pid for pid in children(process.pid)
            if name in Path(f"/proc/{pid}/cmdline").read_text()]
    assert len(pids) == 1, pids
    os.kill(pids[0], signal.SIGKILL)
    return process.communicate(timeout=60)[1]
