"""The control loop's scheduling (nodes/realtime.py): SCHED_FIFO on every thread, or nothing.

The real change runs in a child process (never in the test process); the refusal path is
driven in-process through a scheduler that refuses, so it is checked on any machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any

import pytest

from exo_ilc_ros.nodes import realtime

CHILD = """
import json, os, threading
from exo_ilc_ros.nodes.realtime import fifo_scheduling, thread_policies
gate = threading.Event()
before = [threading.Thread(target=gate.wait) for _ in range(3)]
for t in before:
    t.start()
applied, scheduler = fifo_scheduling({priority})
later = {{}}
def record():
    later["policy"] = os.sched_getscheduler(0)
after = threading.Thread(target=record)
after.start(); after.join()
policies = sorted(set(thread_policies().values()))
gate.set()
print(json.dumps([applied, scheduler, policies, later["policy"], len(before) + 1]))
"""


def _child(priority: int) -> tuple[bool, str, list[int], int]:
    out = subprocess.run([sys.executable, "-c", CHILD.format(priority=priority)],
                         capture_output=True, text=True, check=True, timeout=60)
    applied, scheduler, policies, later, _ = json.loads(out.stdout)
    return applied, scheduler, policies, later


def _fifo_allowed() -> bool:
    probe = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True,
                          check=False).returncode == 0


def test_every_thread_and_the_ones_started_later_run_at_sched_fifo() -> None:
    applied, scheduler, policies, later = _child(50)
    if not _fifo_allowed():
        assert not applied and scheduler.startswith("normal (SCHED_FIFO 50 refused")
        assert policies == [os.SCHED_OTHER] and later == os.SCHED_OTHER
        pytest.skip(f"this machine refuses SCHED_FIFO (checked the refusal): {scheduler}")
    assert applied and scheduler == "SCHED_FIFO 50"
    assert policies == [os.SCHED_FIFO], "every thread, those started before included"
    assert later == os.SCHED_FIFO, "a thread started afterwards inherits it"


def test_priority_zero_leaves_the_scheduler_alone() -> None:
    applied, scheduler, policies, later = _child(0)
    assert not applied and scheduler == "normal (thread_priority 0)"
    assert policies == [os.SCHED_OTHER] and later == os.SCHED_OTHER


def test_a_refusal_puts_back_the_threads_already_changed(monkeypatch: Any) -> None:
    """All threads or none: the kernel refusing the third thread undoes the first two, and
    the reason names what is missing."""
    calls: list[tuple[int, int]] = []

    def refusing(tid: int, policy: int, param: Any) -> None:
        calls.append((tid, policy))
        if policy == os.SCHED_FIFO and sum(p == os.SCHED_FIFO for _, p in calls) == 3:
            raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(realtime.os, "listdir", lambda path: ["11", "12", "13", "14"])
    monkeypatch.setattr(realtime.os, "sched_setscheduler", refusing)
    applied, scheduler = realtime.fifo_scheduling(50)
    assert not applied
    assert scheduler.startswith("normal (SCHED_FIFO 50 refused: Operation not permitted; "
                                "needs CAP_SYS_NICE or an rtprio limit >= 50")
    assert calls[:3] == [(11, os.SCHED_FIFO), (12, os.SCHED_FIFO), (13, os.SCHED_FIFO)]
    assert sorted(calls[3:]) == [(t, os.SCHED_OTHER) for t in (11, 12, 13, 14)]


def test_a_thread_that_ended_meanwhile_is_skipped(monkeypatch: Any) -> None:
    def gone_or_set(tid: int, policy: int, param: Any) -> None:
        if tid == 12:
            raise ProcessLookupError(3, "No such process")

    monkeypatch.setattr(realtime.os, "listdir", lambda path: ["11", "12"])
    monkeypatch.setattr(realtime.os, "sched_setscheduler", gone_or_set)
    assert realtime.fifo_scheduling(70) == (True, "SCHED_FIFO 70")
