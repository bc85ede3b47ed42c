"""Test session set-up: a ROS domain of our own and discovery kept on this machine.

Runs before any test imports rclpy, so every node started in-process or as a subprocess (which
inherits the environment) uses ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a domain id no
other concurrent test session holds (claimed with a lock file, released when the process exits).
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import pytest

_domain_lock: IO[str] | None = None


def _claim_domain_id() -> int:
    global _domain_lock
    for domain in range(1, 101):
        lock = Path(tempfile.gettempdir()) / f".exo_ilc_ros_domain_{domain}.lock"
        handle = open(lock, "w")  # noqa: SIM115  (held open: the lock lives as long as we do)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        _domain_lock = handle
        return domain
    raise RuntimeError("no free ROS domain id in 1..100")


def pytest_configure(config: pytest.Config) -> None:
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    os.environ.pop("RMW_IMPLEMENTATION", None)
    if "EXO_ILC_TEST_DOMAIN_ID" not in os.environ:
        os.environ["EXO_ILC_TEST_DOMAIN_ID"] = str(_claim_domain_id())
    os.environ["ROS_DOMAIN_ID"] = os.environ["EXO_ILC_TEST_DOMAIN_ID"]
    os.environ.setdefault("ROS_LOG_DIR", str(Path(tempfile.gettempdir()) / "exo_ilc_ros_test_logs"))


EXIT_GRACE = 60.0
"""Seconds the process may take to exit after the session ended before the watchdog acts."""


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """An exit watchdog: once, after every test had passed, the process hung at interpreter
    exit for 17 minutes (DDS teardown, not reproduced since), which would cost CI its time limit.
    If the process is still alive ``EXIT_GRACE`` s after the session, every thread's stack goes
    to stderr (for the bug report) and the process exits with the session's own status."""
    import faulthandler
    import sys
    import threading
    import time

    status = int(exitstatus)

    def watchdog() -> None:
        time.sleep(EXIT_GRACE)
        sys.stderr.write(f"\nconftest: the test process did not exit {EXIT_GRACE:g} s after the "
                         f"session ended; thread stacks follow, then exit {status}\n")
        faulthandler.dump_traceback(all_threads=True)
        sys.stderr.flush()
        sys.stdout.flush()
        os._exit(status)

    threading.Thread(target=watchdog, name="exit-watchdog", daemon=True).start()
    # Last resort for a hang in C-level finalisation, where no Python thread runs any more.
    faulthandler.dump_traceback_later(EXIT_GRACE * 2, exit=True)


CHECKOUT = Path(__file__).resolve().parents[1]
LEFT_BEHIND = (CHECKOUT / ".exo-ilc" / "runs", CHECKOUT / "bags")
"""Where a command run from the checkout leaves its stores and bags (``exo-ilc run``'s
defaults): a test runs its commands in a directory of its own (``cwd=tmp_path``)."""


def _left_behind() -> set[Path]:
    return {entry for root in LEFT_BEHIND if root.is_dir() for entry in root.iterdir()}


@pytest.fixture(autouse=True)
def _test_leaves_no_run_in_the_checkout() -> Iterator[None]:
    """No test leaves a store or a bag in the checkout (the suite once left a store in
    .exo-ilc/runs: a command run without ``cwd``)."""
    before = _left_behind()
    yield
    new = sorted(str(p.relative_to(CHECKOUT)) for p in _left_behind() - before)
    assert not new, f"the test left {new} in the checkout: run its commands with cwd=tmp_path"


@pytest.fixture(autouse=True)
def _test_process_keeps_the_normal_scheduler() -> Iterator[None]:
    """No test may leave this process at SCHED_FIFO: every graph and command it starts later
    inherits the policy (a lock-step graph and a study's workers at FIFO starved the machine and
    ate a Ctrl-C in CI). nodes/realtime.py changes scheduling only inside ``run_nodes``."""
    yield
    if hasattr(os, "sched_getscheduler"):
        assert os.sched_getscheduler(0) == os.SCHED_OTHER, "a test left the process at FIFO"
