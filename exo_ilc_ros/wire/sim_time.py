"""The sim time a message is logged at, in the bags and the live view: the rule of
``ros2 bag record --use-sim-time`` (the recorder's sim clock at receipt), with the graph's
sample stamps as clock ticks too.

:class:`SimClock` advances (never back) to every sim stamp it sees, in receive order:
``/clock`` and the header stamps of ``/joint_states``, the trial events, the summaries and the
feed-forward (:data:`SIM_STAMPED`). So each sample and /clock message is logged at its own
stamp, and a message without one (an effort command, the trial metrics, /diagnostics, whose
stamps lag the clock) at the sim time of the last stamped message received before it.
"""

from __future__ import annotations

import struct

from . import topics

SIM_STAMPED = frozenset({topics.CLOCK, topics.JOINT_STATES, topics.TRIAL_EVENTS,
                         topics.TRIAL_SUMMARY, topics.FEEDFORWARD, *topics.CUFF_WRENCHES})
"""Topics whose messages start with a sim-time stamp (``/clock``'s clock, else
``header.stamp``) that advances the clock (the plant's and the supervisor's messages; a
person's cuff wrenches, stamped as their sample)."""


def sim_stamp(raw: bytes) -> int | None:
    """The ``builtin_interfaces/Time`` at the start of a CDR message, in ns (None if the
    message is too short to hold one)."""
    if len(raw) < 12:
        return None
    order = "<" if raw[1] == 1 else ">"
    sec, nanosec = struct.unpack_from(order + "iI", raw, 4)
    return sec * 1_000_000_000 + nanosec


class SimClock:
    """The running sim time of a stream of messages (module docstring)."""

    def __init__(self) -> None:
        self.ns = 0
        """The largest sim stamp seen so far (0 before the first)."""

    def advance(self, topic: str, raw: bytes) -> int:
        """The log time of ``raw`` on ``topic``, received after every message seen so far."""
        if topic in SIM_STAMPED:
            stamp = sim_stamp(raw)
            if stamp is not None and stamp > self.ns:
                self.ns = stamp
        return self.ns
