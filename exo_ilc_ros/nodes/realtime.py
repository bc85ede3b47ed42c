"""The control loop's scheduling: every thread of the process at ``SCHED_FIFO``.

On a 2-core machine shared with the supervisor, the recorder and whatever else runs, a control
loop at the normal (CFS) priority is descheduled for milliseconds at times, and at 1 kHz every
such pause is a command applied a period late. ros2_control's controller_manager runs its loop
thread at ``SCHED_FIFO`` priority 50 (its ``thread_priority`` parameter) for this reason; the
computed-torque controller and a real-time plant do the same with ``thread_priority``. The
priority goes to every thread the process has (the DDS receive threads deliver the samples) and
is inherited by the threads they start. Without ``CAP_SYS_NICE`` or an ``rtprio`` limit
(``/etc/security/limits.conf``) the kernel refuses it: the node then says so and runs at the
normal priority. Measured with ``bench/realtime_bench.py`` (README "Real time").
"""

from __future__ import annotations

import contextlib
import os
import resource

NORMAL = "normal"


def fifo_scheduling(priority: int) -> tuple[bool, str]:
    """Every thread of this process at ``SCHED_FIFO`` ``priority`` (1..99; 0 leaves the
    scheduler alone). Returns (whether it is in effect, what the process runs at: ``SCHED_FIFO
    50``, or ``normal`` with the reason), for the node's log and health."""
    if priority <= 0:
        return False, f"{NORMAL} (thread_priority 0)"
    if not hasattr(os, "SCHED_FIFO"):
        return False, f"{NORMAL} (no SCHED_FIFO on this system)"
    param = os.sched_param(priority)
    try:
        threads = [int(tid) for tid in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]  # no /proc: this thread only
    done = 0
    for tid in threads:
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO, param)
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


def thread_policies() -> dict[int, int]:
    """Thread id -> scheduling policy of every thread of this process (for tests)."""
    return {int(tid): os.sched_getscheduler(int(tid)) for tid in os.listdir("/proc/self/task")}
