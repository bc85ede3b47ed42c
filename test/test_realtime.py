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
from exo_ilc_ros.nodes.realtime import fifo_scheduling, node_process, thread_policies, policy_of
import contextlib
context = node_process() if {node} else contextlib.nullcontext()
context.__enter__()
gate = threading.Event()
before = [threading.Thread(target=gate.wait, daemon=True) for _ in range(3)]
for t in before:
    t.start()
applied, scheduler = fifo_scheduling({priority})
later = {{}}
def record():
    later["policy"] = policy_of(0)
after = threading.Thread(target=record)
after.start(); after.join()
policies = sorted(set(thread_policies().values()))
gate.set()
print(json.dumps([applied, scheduler, policies, later["policy"], len(before) + 1]))
"""


def _child(priority: int, node: bool = True) -> tuple[bool, str, list[int], int]:
    out = subprocess.run([sys.executable, "-c", CHILD.format(priority=priority, node=node)],
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


def test_a_node_inside_another_program_leaves_its_scheduling_alone() -> None:
    """A node built in a test or a notebook (not through run_nodes) must not put that program
    at SCHED_FIFO (a test process at FIFO passed it on to every graph it started)."""
    applied, scheduler, policies, later = _child(50, node=False)
    assert not applied and scheduler == "normal (a node inside another program: its " \
        "scheduling is left alone)"
    assert policies == [os.SCHED_OTHER] and later == os.SCHED_OTHER


def test_a_refusal_puts_back_the_threads_already_changed(monkeypatch: Any) -> None:
    """All threads or none: the kernel refusing the third thread undoes the first two, and
    the reason names what is missing."""
    calls: list[tuple[int, int]] = []
    fifo = os.SCHED_FIFO

    def refusing(tid: int, policy: int, param: Any) -> None:
        calls.append((tid, policy))
        if policy == fifo and sum(p == fifo for _, p in calls) == 3:
            raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(realtime, "_NODE_PROCESS", True)
    monkeypatch.setattr(realtime.os, "listdir", lambda path: ["11", "12", "13", "14"])
    monkeypatch.setattr(realtime.os, "sched_setscheduler", refusing)
    applied, scheduler = realtime.fifo_scheduling(50)
    assert not applied
    assert scheduler.startswith("normal (SCHED_FIFO 50 refused: Operation not permitted; "
                                "needs CAP_SYS_NICE or an rtprio limit >= 50")
    assert calls[:3] == [(11, fifo), (12, fifo), (13, fifo)]
    assert sorted(calls[3:]) == [(t, os.SCHED_OTHER) for t in (11, 12, 13, 14)]


def test_a_thread_that_ended_meanwhile_is_skipped(monkeypatch: Any) -> None:
    def gone_or_set(tid: int, policy: int, param: Any) -> None:
        if tid == 12:
            raise ProcessLookupError(3, "No such process")

    monkeypatch.setattr(realtime, "_NODE_PROCESS", True)
    monkeypatch.setattr(realtime.os, "listdir", lambda path: ["11", "12"])
    monkeypatch.setattr(realtime.os, "sched_setscheduler", gone_or_set)
    assert realtime.fifo_scheduling(70) == (True, "SCHED_FIFO 70")


class _Future:
    def __init__(self, result: Any) -> None:
        self._result = result

    def done(self) -> bool:
        return True

    def result(self) -> Any:
        return self._result


@pytest.mark.parametrize(("answer", "fifo", "said"), [
    ("lock_step", False, "normal (plant_simulator is lock-step)"),
    ("real_time", True, "plant_simulator mode 'real_time'"),
    (None, True, "plant_simulator has no mode parameter (an arm of its own)"),
    ("silent", True, "no parameters from plant_simulator after 5 s"),
])
def test_the_controller_asks_the_plant_before_it_takes_sched_fifo(
        monkeypatch: Any, answer: str | None, fifo: bool, said: str) -> None:
    """LoopPriority: lock-step keeps the normal scheduler (the ping-pong at FIFO starved the
    machine); real time, a node without ``mode`` (joint_state_broadcaster) or no parameter
    service within PLANT_WAIT (an arm of your own) take SCHED_FIFO."""
    from types import SimpleNamespace

    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rclpy import parameter_client

    asked: list[int] = []
    logged: list[str] = []
    monkeypatch.setattr(realtime, "fifo_scheduling",
                        lambda p: (asked.append(p) or True, f"SCHED_FIFO {p}"))
    clock = [100.0]
    monkeypatch.setattr(realtime.time, "monotonic", lambda: clock[0])

    class Client:
        def __init__(self, node: Any, name: str) -> None:
            assert name == "plant_simulator"

        def services_are_ready(self) -> bool:
            return answer != "silent"

        def get_parameters(self, names: list[str]) -> _Future:
            assert names == ["mode"]
            value = ParameterValue() if answer is None else ParameterValue(
                type=ParameterType.PARAMETER_STRING, string_value=answer)
            return _Future(SimpleNamespace(values=[value]))

    monkeypatch.setattr(parameter_client, "AsyncParameterClient", Client)
    node = SimpleNamespace(get_logger=lambda: SimpleNamespace(
        info=logged.append, warning=logged.append))
    loop = realtime.LoopPriority(node, "plant_simulator", 50)
    assert not loop.decided and loop.scheduler == "normal (asking plant_simulator for its mode)"
    for _ in range(3):
        loop.poll()
        clock[0] += 3.0  # the silent plant: past PLANT_WAIT after two polls
    assert loop.decided
    assert asked == ([50] if fifo else [])
    assert (loop.scheduler == "SCHED_FIFO 50") == fifo
    assert said in (logged[0] if fifo else loop.scheduler), (logged, loop.scheduler)
    off = realtime.LoopPriority(node, "plant_simulator", 0)
    assert off.decided and off.scheduler == "normal (thread_priority 0)"
