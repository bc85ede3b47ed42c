"""The watchdog, ROS-free: no input for too long during a trial -> the safe hold.

The other safety rules live with the kernel they guard: the error envelope and the safe hold in
:mod:`.controller` (``outside_envelope``, ``safe_hold_into``), the effort clamp and the
saturation count in :mod:`.plant` (``clamp``, ``clamp_counted``, ``saturation_counts``), the
input checks in :mod:`.validation`.
"""

from __future__ import annotations

from enum import Enum
from typing import Protocol


class WatchdogState(Enum):
    """Where the watchdog is."""

    IDLE = "idle"
    """Not expecting input (between trials)."""
    RUNNING = "running"
    """Input is arriving in time."""
    TIMED_OUT = "timed_out"
    """No input for longer than the timeout: command the safe hold (latched until re-armed)."""


class Watchdog:
    """No input for ``periods`` control periods -> TIMED_OUT (latched until :meth:`arm`).

    Times are integer nanoseconds of any monotonic clock the caller chooses (a steady clock in
    lock-step mode, where simulated time stands still without input). The controller feeds it
    with every /joint_states message and commands the safe hold while :attr:`tripped`; the plant
    feeds it with every command and stops holding the last command once tripped.
    """

    def __init__(self, periods: int, period_ns: int, min_timeout_ns: int = 0) -> None:
        if periods < 1 or period_ns < 1 or min_timeout_ns < 0:
            raise ValueError(f"watchdog needs periods >= 1, period_ns >= 1 and min_timeout_ns "
                             f">= 0, got {periods}, {period_ns} and {min_timeout_ns}")
        self.timeout_ns = max(int(periods) * int(period_ns), int(min_timeout_ns))
        """``periods`` control periods, but never less than ``min_timeout_ns``."""
        self.state = WatchdogState.IDLE
        self.last_ns = 0
        self.trips = 0
        """How many times it timed out since construction."""
        self.late = 0
        """Inputs that arrived while timed out (ignored until re-armed)."""

    @property
    def tripped(self) -> bool:
        """True while the safe hold must be commanded."""
        return self.state is WatchdogState.TIMED_OUT

    def arm(self, now_ns: int) -> None:
        """Start expecting input (trial start); clears a trip."""
        self.state = WatchdogState.RUNNING
        self.last_ns = int(now_ns)

    def disarm(self) -> None:
        """Stop expecting input (trial end)."""
        self.state = WatchdogState.IDLE

    def feed(self, now_ns: int) -> bool:
        """An input arrived; returns False if it is ignored (timed out or idle)."""
        if self.state is WatchdogState.TIMED_OUT:
            self.late += 1
            return False
        if self.state is WatchdogState.IDLE:
            return False
        self.check(now_ns)
        if self.tripped:
            self.late += 1
            return False
        self.last_ns = int(now_ns)
        return True

    def check(self, now_ns: int) -> bool:
        """Call periodically; returns True exactly once, on the transition to TIMED_OUT."""
        if self.state is WatchdogState.RUNNING and int(now_ns) - self.last_ns > self.timeout_ns:
            self.state = WatchdogState.TIMED_OUT
            self.trips += 1
            return True
        return False

    def as_values(self) -> list[tuple[str, str]]:
        """Key-values for a diagnostic status."""
        return [("state", self.state.value), ("trips", str(self.trips)),
                ("late_inputs", str(self.late)), ("timeout_ns", str(self.timeout_ns))]


class _Parameters(Protocol):
    def __getitem__(self, name: str) -> object: ...


def watchdog_for(config: _Parameters) -> Watchdog:
    """The one rule of both watchdogs, the controller's (no /joint_states) and the real-time
    plant's (no command): ``safety.watchdog_periods`` control periods of wall time, never less
    than ``watchdog_min_timeout`` (default 1 s: a loaded 2-core machine delivers late without
    any fault, and a trip costs a re-run; 0 on hardware, where the periods alone count)."""
    period_ns = int(round(float(str(config["control.period"])) * 1e9))
    return Watchdog(int(str(config["safety.watchdog_periods"])), period_ns,
                    int(round(float(str(config["watchdog_min_timeout"])) * 1e9)))


class LateCommands:
    """Real-time plant: periods run on a late command. Each tick applies the last command
    received; if none arrived since the previous tick, the command meant for this period is
    late (it will be applied a period or more after its sample) and the one before is held."""

    def __init__(self) -> None:
        self.trial = 0
        """Late periods in the running (or last) trial."""
        self.periods = 0
        """Periods stepped in the running (or last) trial."""
        self.first = -1
        """The first late period of the running (or last) trial (1-based; -1: none)."""
        self.total = 0
        self._fresh = False

    def start(self) -> None:
        """A trial starts (sample 0 is out; its command is due before the first tick)."""
        self.trial = self.periods = 0
        self.first = -1
        self._fresh = False

    def command(self) -> None:
        """A command arrived."""
        self._fresh = True

    def tick(self) -> None:
        """A period is stepped with the command held now."""
        self.periods += 1
        if not self._fresh:
            self.trial += 1
            self.total += 1
            if self.first < 0:
                self.first = self.periods
        self._fresh = False

    def as_values(self) -> list[tuple[str, str]]:
        """Key-values for the plant's health."""
        return [("late_commands", str(self.trial)), ("late_periods", str(self.periods)),
                ("first_late", str(self.first)), ("late_commands_total", str(self.total))]
