"""The live tests' pair of WebSocket clients of one ``exo-ilc run --live`` (one from the start,
one late), on a free port."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

from live_client import Received, collect
from processes import children

from exo_ilc_ros.wire import topics


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the default 8765 may be held by another test session
    on the machine)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LiveClients:
    """Two WebSocket clients of a live view about to start on a free ``port``: ``received``
    connects at once (retrying until the view serves) and collects from the start; ``late``
    connects once trial 1's metrics went out, so it must get again what came before it (no
    latching in the protocol: the view re-sends the descriptions and every trial's metrics on
    subscribe). Both collect until the server closes the connection.

    The run (:meth:`run`) waits for the late client: once the first client has trial 1's
    metrics, the run's supervisor is stopped (SIGSTOP: no trial concludes, none starts, the run
    cannot end) until the late client subscribed, then continued; the lock-step trials' numbers
    do not depend on when their steps happen. What is left to the machine is only that the
    stop (a 10 ms poll and a signal) comes before the run's last trial concluded, not that a
    WebSocket handshake does (it did not, at a load of 4)."""

    CONNECT_TIMEOUT = 120.0
    """Seconds the first client keeps trying to connect (the run's graph starts first)."""
    LATE_WAIT = 250.0
    """Seconds the late client waits for trial 1's metrics before connecting anyway."""

    def __init__(self) -> None:
        self.port = free_port()
        self.url = f"ws://127.0.0.1:{self.port}"
        self.received = Received()
        self.late = Received()
        self._run: subprocess.Popen[str] | None = None
        self._running = threading.Event()
        self._first = threading.Thread(target=collect, args=(self.url, self.CONNECT_TIMEOUT),
                                       kwargs={"received": self.received}, daemon=True)
        self._second = threading.Thread(target=self._join_late, daemon=True)
        self._first.start()
        self._second.start()

    def run(self, argv: list[str], timeout: float) -> subprocess.CompletedProcess[str]:
        """``exo-ilc`` with ``argv`` (a ``run --live --live-port PORT``) to its end, while the
        clients collect; its output."""
        process = subprocess.Popen([sys.executable, "-m", "exo_ilc_ros.cli.main", *argv],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   stdin=subprocess.DEVNULL, text=True)
        self._run = process
        self._running.set()
        try:
            out, err = process.communicate(timeout=timeout)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
        return subprocess.CompletedProcess(process.args, process.returncode, out, err)

    def _supervisors(self) -> list[int]:
        """The run's supervisor process (the recorder in it, by default)."""
        assert self._run is not None
        found = []
        for pid in children(self._run.pid):
            with contextlib.suppress(FileNotFoundError):
                if "ilc_supervisor" in Path(f"/proc/{pid}/cmdline").read_text():
                    found.append(pid)
        return found

    def _join_late(self) -> None:
        deadline = time.monotonic() + self.LATE_WAIT
        while not self.received.messages.get(topics.TRIAL_METRICS) and \
                time.monotonic() < deadline:
            time.sleep(0.01)
        self._running.wait(self.LATE_WAIT)
        held = self._supervisors()
        for pid in held:
            os.kill(pid, signal.SIGSTOP)
        late = threading.Thread(target=collect, args=(self.url, 30.0),
                                kwargs={"received": self.late}, daemon=True)
        late.start()
        try:
            while self.late.first_subscribed is None and late.is_alive():
                time.sleep(0.01)
        finally:
            for pid in held:
                os.kill(pid, signal.SIGCONT)
        late.join()

    def finish(self) -> None:
        """After the run exited: both clients were closed by the server, and the late one
        subscribed after the first."""
        self._first.join(30)
        self._second.join(30)
        assert not self._first.is_alive(), "the server did not close the connection at the end"
        assert not self._second.is_alive(), "the server did not close the late connection"
        assert self.late.first_subscribed is not None and \
            self.received.first_subscribed is not None
        assert self.late.first_subscribed > self.received.first_subscribed
