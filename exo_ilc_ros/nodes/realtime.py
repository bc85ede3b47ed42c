"""The control loop's scheduling: every thread of the process at ``SCHED_FIFO``.

On a 2-core machine shared with the supervisor, the recorder and whatever else runs, a control
loop at the normal (CFS) priority is descheduled for milliseconds at times, and at 1 kHz every
such pause is a command applied a period late. ros2_control's controller_manager runs its loop
thread at ``SCHED_FIFO`` priority 50 (its ``thread_priority`` parameter) for this reason; the
computed-torque controller and a real-time plant do the same with ``thread_priority``. The
priority goes to every thread the process has (the DDS receive threads deliver the samples) and
is inherited by the threads they start (``SCHED_RESET_ON_FORK`` would stop that too: the kernel
treats a new thread as a fork).

Only where a loop is real time: a lock-step plant and its controller ping-pong as fast as they
can, and at ``SCHED_FIFO`` (whose threads a yield does not hand to normal ones) they starved
every other process of the machine (seen: load average 70, a CI run stalled). So a plant asks
for it only in ``mode: real_time``, and the controller only once the node whose /joint_states
it acts on says it is not lock-step (:class:`LoopPriority`). And only in a node's own process
(:func:`node_process`, called by ``nodes.common.run_nodes``): a node built inside another
program (a test, a notebook) leaves that program's scheduling alone.

Without ``CAP_SYS_NICE`` or an ``rtprio`` limit (``/etc/security/limits.conf``) the kernel
refuses it: the node then says so and runs at the normal priority. Measured with
``bench/realtime_bench.py`` (docs/hostile-input.md "Real time").
"""

from __future__ import annotations

import contextlib
import os
import resource
import time
from collections.abc import Iterator
from typing import Any

NORMAL = "normal"
PLANT_WAIT = 5.0
"""s the controller waits for the mode of the node whose /joint_states it acts on; no answer
by then: an arm of your own, real time."""
_NODE_PROCESS = False


@contextlib.contextmanager
def node_process() -> Iterator[None]:
    """While ``nodes.common.run_nodes`` runs nodes in this process: their requests are carried
    out. Only while: a test that ran ``run_nodes`` in-process and then built a real-time plant
    put the pytest process at SCHED_FIFO, and a study it started later (its workers at FIFO
    too) never let its main thread handle Ctrl-C (seen in CI)."""
    global _NODE_PROCESS
    before, _NODE_PROCESS = _NODE_PROCESS, True
    try:
        yield
    finally:
        _NODE_PROCESS = before


def fifo_scheduling(priority: int) -> tuple[bool, str]:
    """Every thread of this process at ``SCHED_FIFO`` ``priority`` (1..99; 0 leaves the
    scheduler alone). Returns (whether it is in effect, what the process runs at: ``SCHED_FIFO
    50``, or ``normal`` with the reason), for the node's log and health."""
    if priority <= 0:
        return False, f"{NORMAL} (thread_priority 0)"
    if not _NODE_PROCESS:
        return False, f"{NORMAL} (a node inside another program: its scheduling is left alone)"
    if not hasattr(os, "SCHED_FIFO"):
        return False, f"{NORMAL} (no SCHED_FIFO on this system)"
    param = os.sched_param(priority)
    policy = os.SCHED_FIFO
    threads = own_threads()
    done = 0
    for tid in threads:
        try:
            os.sched_setscheduler(tid, policy, param)
            done += 1
        except ProcessLookupError:  # a thread that ended meanwhile
            continue
        except OSError as exc:
            if done:  # some threads are FIFO already: put them back, all or none
                for back in threads:
                    with contextlib.suppress(OSError):
                        os.sched_setscheduler(back, os.SCHED_OTHER, os.sched_param(0))
            soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
            return False, (f"{NORMAL} (SCHED_FIFO {priority} refused: {exc.strerror}; needs "
                           f"CAP_SYS_NICE or an rtprio limit >= {priority}, now {soft})")
    return True, f"SCHED_FIFO {priority}"


def own_threads() -> list[int]:
    """This process's thread ids (``[0]``, the calling thread, where there is no /proc)."""
    try:
        return [int(tid) for tid in os.listdir("/proc/self/task")]
    except OSError:
        return [0]


def plant_scheduling(node: Any, priority: int, lock_step: bool) -> str:
    """A plant's side: ``SCHED_FIFO`` ``priority`` in real time, nothing in lock-step (no
    clock to keep); warns when refused. Returns what the process runs at, for the health."""
    applied, scheduler = fifo_scheduling(0 if lock_step else priority)
    if priority and not lock_step and not applied:
        node.get_logger().warning(f"real-time plant at the {scheduler}")
    return scheduler


def policy_of(tid: int) -> int:
    """The scheduling policy of thread (or process) ``tid``."""
    return os.sched_getscheduler(tid)


def thread_policies(pid: int | str = "self") -> dict[int, int]:
    """Thread id -> scheduling policy of every thread of process ``pid`` (a thread that ends
    between the listing and the query is left out: a joined thread can still be listed)."""
    policies = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        with contextlib.suppress(ProcessLookupError):
            policies[int(tid)] = policy_of(int(tid))
    return policies


class LoopPriority:
    """The controller's side: ``SCHED_FIFO`` ``priority`` once the node whose /joint_states it
    acts on (``publisher``) is known not to be lock-step. Our plants answer their ``mode``
    parameter; a node without it (ros2_control's joint_state_broadcaster) or no parameter
    service within :data:`PLANT_WAIT` s means an arm with its own clock: real time.
    :meth:`poll` until :attr:`decided`; :attr:`scheduler` is what the process runs at."""

    def __init__(self, node: Any, publisher: str, priority: int) -> None:
        self.node = node
        self.priority = priority
        self.decided = priority <= 0
        self.scheduler = f"{NORMAL} (thread_priority 0)" if self.decided else \
            f"{NORMAL} (asking {publisher} for its mode)"
        self.publisher = publisher
        self._client: Any = None
        self._future: Any = None
        self._since = time.monotonic()

    def poll(self) -> None:
        """One step of the decision (a timer calls it until :attr:`decided`)."""
        if self.decided:
            return
        if self._client is None:
            from rclpy.parameter_client import AsyncParameterClient

            self._client = AsyncParameterClient(self.node, self.publisher)
        if self._future is None:
            if self._client.services_are_ready():
                self._future = self._client.get_parameters(["mode"])
            elif time.monotonic() - self._since > PLANT_WAIT:
                self._decide(f"no parameters from {self.publisher} after {PLANT_WAIT:g} s")
            return
        if not self._future.done():
            return
        from rcl_interfaces.msg import ParameterType

        result = self._future.result()
        values = [] if result is None else list(result.values)
        mode = values[0].string_value if values and \
            values[0].type == ParameterType.PARAMETER_STRING else ""
        if mode == "lock_step":
            self.decided = True
            self.scheduler = f"{NORMAL} ({self.publisher} is lock-step)"
            self.node.get_logger().info(f"{self.publisher} is lock-step: the control loop "
                                        "keeps the normal scheduler")
        else:
            self._decide(f"{self.publisher} mode {mode!r}" if mode else
                         f"{self.publisher} has no mode parameter (an arm of its own)")

    def _decide(self, why: str) -> None:
        self.decided = True
        applied, self.scheduler = fifo_scheduling(self.priority)
        log = self.node.get_logger()
        if applied:
            log.info(f"{why}: control loop at {self.scheduler}")
        else:
            log.warning(f"{why}: control loop at the {self.scheduler}")
