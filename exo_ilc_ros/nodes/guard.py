"""Input gates and health reporting shared by the nodes (thin wrappers of core.loop.wire_input).

:class:`JointStateGate` checks every /joint_states message before a node uses it: names (a
message naming the configured joints in another order is reordered), lengths, finite values,
stamps strictly increasing. The common case (the plant's own layout) costs a bytes compare and
one ``isfinite``; anything else goes through :func:`core.loop.wire_input.validate_joint_state`.
Rejections are counted per cause (:class:`core.loop.wire_input.LogOnce`), logged once per
cause, and reported on /diagnostics by :class:`Health`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from math import isfinite

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node

from ..core.loop.wire_input import Cause, LogOnce, Rejection, validate_joint_state
from ..wire.cdr import (
    HEADER,
    STAMP,
    CdrError,
    joint_state_offsets,
    names_segment,
    read_joint_state,
    read_joint_state_full,
)
from .diagnostics import status

LEVEL_NAMES = {DiagnosticStatus.OK: "OK", DiagnosticStatus.WARN: "WARN",
               DiagnosticStatus.ERROR: "ERROR"}


def health_status_name(node: str) -> str:
    """The name of a node's health status on /diagnostics."""
    return f"{node}/health"


class Rejections:
    """LogOnce plus the node's logger: the first rejection of each cause is logged (error; a
    warning for a writer discovery has not listed yet), later ones only counted."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.log = LogOnce()

    def reject(self, rejection: Rejection) -> None:
        """Count ``rejection``; log it if its cause is new."""
        if not self.log.record(rejection):
            return
        text = (f"rejected ({rejection.cause.value}): {rejection.message}; further "
                f"{rejection.cause.value} rejections are counted on /diagnostics")
        # Two call sites: rclpy's logger refuses one call site with two severities (ValueError).
        if rejection.cause is Cause.UNLISTED_PUBLISHER:
            self.node.get_logger().warning(text)
        else:
            self.node.get_logger().error(text)

    def reject_cause(self, cause: Cause, message: str) -> None:
        """Count a rejection given as cause and message."""
        self.reject(Rejection(cause, message))


@dataclass(frozen=True)
class _Layout:
    """A serialised JointState's byte layout: ``names`` (frame_id, names and the position
    count) and ``gap`` (the velocity count) must match byte for byte, then the doubles at
    ``position`` and ``velocity`` are the values."""

    size: int
    names: slice
    names_bytes: bytes
    gap: slice
    gap_bytes: bytes
    position: int
    velocity: int
    doubles: struct.Struct

    @classmethod
    def of(cls, raw: bytes, n: int) -> _Layout | None:
        """The layout of ``raw``, a message already validated with n positions and n
        velocities, or None if it cannot be decoded."""
        try:
            position, velocity = joint_state_offsets(raw)
        except CdrError:
            return None
        names, gap = slice(12, position), slice(position + 8 * n, velocity)
        return cls(len(raw), names, raw[names], gap, raw[gap], position, velocity,
                   struct.Struct(f"<{n}d"))


class JointStateGate:
    """Validated (stamp, position, velocity) from raw /joint_states bytes, or None."""

    def __init__(self, joint_names: Sequence[str], rejections: Rejections) -> None:
        self.joint_names = list(joint_names)
        self.n = len(self.joint_names)
        self.rejections = rejections
        self.fast_names: bytes | None = None
        """The names segment of the last message whose names were exactly joint_names."""
        self.last_stamp_ns: int | None = None
        self.window: tuple[int, int] | None = None
        """Stamps a message may carry (the running trial's first and last sample): one outside
        is rejected without touching ``last_stamp_ns``, so a stamp far in the future costs one
        message, not the rest of the trial."""
        self.layout: _Layout | None = None
        """Where the values sit in a message of the last accepted layout with these names."""

    def restart(self, window: tuple[int, int] | None = None) -> None:
        """Forget the last stamp (a new trial: the plant may have been restarted); accept only
        stamps within ``window`` (first, last sample of the trial; None: any)."""
        self.last_stamp_ns = None
        self.window = window

    def _in_window(self, stamp: int) -> bool:
        window = self.window
        return window is None or window[0] <= stamp <= window[1]

    def __call__(self, raw: bytes) -> tuple[int, np.ndarray, np.ndarray] | None:
        layout = self.layout
        if layout is not None and len(raw) == layout.size and raw[:2] == HEADER[:2] and \
                raw[layout.names] == layout.names_bytes and raw[layout.gap] == layout.gap_bytes:
            # The plant's own layout again: only the stamp and the values can differ.
            values = layout.doubles.unpack_from(raw, layout.position) + \
                layout.doubles.unpack_from(raw, layout.velocity)
            sec, nanosec = STAMP.unpack_from(raw, 4)
            stamp = sec * 1_000_000_000 + nanosec
            if isfinite(sum(values)) and stamp >= 0 and self._in_window(stamp) and \
                    (self.last_stamp_ns is None or stamp > self.last_stamp_ns):
                self.last_stamp_ns = stamp
                n = self.n
                return (stamp, np.frombuffer(raw, "<f8", n, layout.position),
                        np.frombuffer(raw, "<f8", n, layout.velocity))
        try:
            segment = names_segment(raw)
            if segment == self.fast_names:
                stamp, position, velocity = read_joint_state(raw)
                if position.shape[0] == self.n and velocity.shape[0] == self.n and \
                        np.isfinite(position).all() and np.isfinite(velocity).all() and \
                        stamp >= 0 and self._in_window(stamp) and \
                        (self.last_stamp_ns is None or stamp > self.last_stamp_ns):
                    self.last_stamp_ns = stamp
                    return stamp, position, velocity
            stamp, names, position, velocity, effort = read_joint_state_full(raw)
        except CdrError as exc:
            self.rejections.reject_cause(Cause.NOT_NUMERIC, f"/joint_states: undecodable: {exc}")
            return None
        sample = validate_joint_state(names, stamp, position.tolist(), velocity.tolist(),
                                      effort.tolist(), self.joint_names,
                                      self.last_stamp_ns)
        if isinstance(sample, Rejection):
            self.rejections.reject(sample)
            return None
        if not self._in_window(sample.stamp_ns):
            assert self.window is not None
            self.rejections.reject_cause(
                Cause.BAD_STAMP, f"/joint_states: stamp {sample.stamp_ns} ns is outside the "
                f"running trial's samples [{self.window[0]}, {self.window[1]}] ns")
            return None
        if names == self.joint_names:
            self.fast_names = segment
            self.layout = _Layout.of(raw, self.n)
        self.last_stamp_ns = sample.stamp_ns
        return sample.stamp_ns, sample.position, sample.velocity


class Health:
    """A node's health on /diagnostics: OK, WARN or ERROR with the reasons, and key-values.

    ``checks`` are called at each report; each returns (level, reason or "") and key-values.
    """

    def __init__(self, node: Node, name: str) -> None:
        self.node = node
        self.name = name
        self.checks: list[Callable[[], tuple[bytes, str, list[tuple[str, str]]]]] = []

    def status(self) -> DiagnosticStatus:
        """The current health status."""
        level = DiagnosticStatus.OK
        reasons: list[str] = []
        values: list[tuple[str, str]] = []
        for check in self.checks:
            item_level, reason, item_values = check()
            if reason:
                reasons.append(reason)
            if item_level > level:
                level = item_level
            values += item_values
        message = "; ".join(reasons) if reasons else "ok"
        return status(health_status_name(self.name), message, values, level, self.name)


def rejections_check(rejections: Rejections, what: str
                     ) -> Callable[[], tuple[bytes, str, list[tuple[str, str]]]]:
    """A health check: WARN once any input was rejected, with the counts per cause."""
    def check() -> tuple[bytes, str, list[tuple[str, str]]]:
        log = rejections.log
        if not log.total:
            return DiagnosticStatus.OK, "", []
        causes = ", ".join(f"{c.value} x{n}" for c, n in log.counts.items())
        return DiagnosticStatus.WARN, f"{what} rejected: {causes}", log.as_values()
    return check


def effort_limit_reasons(names: Sequence[str], saturated: np.ndarray, over_limit: int
                         ) -> tuple[bytes, list[str]]:
    """A plant's effort-limit health: WARN with the joints whose effort reached the limit
    (samples per joint) and the count of commands clamped beyond it; OK and none otherwise."""
    level = DiagnosticStatus.OK
    reasons = []
    if saturated.any():
        level = DiagnosticStatus.WARN
        reasons.append("effort at the limit in " + ", ".join(
            f"{n} x{int(c)}" for n, c in zip(names, saturated, strict=True) if c))
    if over_limit:
        level = DiagnosticStatus.WARN
        reasons.append(f"{over_limit} commands beyond the limit clamped")
    return level, reasons
