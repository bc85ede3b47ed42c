"""What arrives on the wire, checked beside the loop that acts on it, ROS-free.

Each validator takes plain Python/numpy data as a node extracts it from a message and returns
either the clean value (arrays in the ``joint_names`` order, float64) or a :class:`Rejection`
with a :class:`Cause` and a message saying what and where. None raises on bad input.
:class:`LogOnce` counts rejections per cause so a node logs each cause once, with a count.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np


class Cause(Enum):
    """Why an input was rejected (one log line per cause, with a count)."""

    NOT_NUMERIC = "not_numeric"
    NON_FINITE = "non_finite"
    WRONG_LENGTH = "wrong_length"
    UNKNOWN_JOINT = "unknown_joint"
    DUPLICATE_JOINT = "duplicate_joint"
    MISSING_JOINT = "missing_joint"
    NON_MONOTONIC_STAMP = "non_monotonic_stamp"
    BAD_STAMP = "bad_stamp"
    OUT_OF_LIMIT = "out_of_limit"
    WRONG_TIMES = "wrong_times"
    OVERSIZED = "oversized"
    """More bytes than a message of the contract may have: refused before decoding."""
    FOREIGN_PUBLISHER = "foreign_publisher"
    """A well-formed message from a publisher other than the contract's (wire.publishers)."""
    UNLISTED_PUBLISHER = "unlisted_publisher"
    """A well-formed message from a writer the ROS graph does not list yet, even after a fresh
    look (discovery lags a publisher's first messages at start-up): refused like a foreign
    one, but reported as a warning, not as another publisher."""


@dataclass(frozen=True)
class Rejection:
    """An input refused: the cause code and a message for humans."""

    cause: Cause
    message: str

    def __str__(self) -> str:
        return f"{self.cause.value}: {self.message}"


@dataclass(frozen=True, eq=False)
class JointSample:
    """A validated JointState: stamp and arrays in the configured joint order."""

    stamp_ns: int
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray | None
    """None when the message carried no effort (allowed by sensor_msgs/JointState)."""


@dataclass(frozen=True, eq=False)
class FeedforwardProfile:
    """A validated feed-forward profile: (samples, joints) arrays in the configured order."""

    position: np.ndarray
    velocity: np.ndarray
    feedforward: np.ndarray
    joint_force: np.ndarray | None = None
    """The identified joint forces computed torque adds (N m; the points' ``effort``), None:
    the points carry none."""


def _numbers(values: Any, what: str, where: str) -> np.ndarray | Rejection:
    """``values`` as a float64 array, or NOT_NUMERIC / NON_FINITE."""
    if isinstance(values, (list, tuple)) and any(isinstance(v, bool) for v in values):
        return Rejection(Cause.NOT_NUMERIC, f"{where}: {what} holds a bool")
    try:
        raw = np.asarray(values)
    except (TypeError, ValueError) as exc:  # ragged nesting
        return Rejection(Cause.NOT_NUMERIC, f"{where}: {what} is not numeric ({exc})")
    if raw.dtype.kind not in "fiu":  # strings, bools, objects, complex
        return Rejection(Cause.NOT_NUMERIC, f"{where}: {what} is not numeric ({raw.dtype})")
    array = raw.astype(np.float64)
    bad = np.flatnonzero(~np.isfinite(array.ravel()))
    if bad.size:
        index = np.unravel_index(int(bad[0]), array.shape) if array.ndim > 1 else int(bad[0])
        return Rejection(Cause.NON_FINITE, f"{where}: {what}[{index}] is "
                         f"{array.ravel()[bad[0]]!r} ({bad.size} non-finite)")
    return array


def joint_order(names: Sequence[str], joint_names: Sequence[str],
                where: str) -> np.ndarray | Rejection:
    """Index into the message's arrays for each configured joint (reorders by name), or
    UNKNOWN_JOINT / DUPLICATE_JOINT / MISSING_JOINT."""
    names = list(names)
    if any(not isinstance(n, str) for n in names):
        return Rejection(Cause.UNKNOWN_JOINT, f"{where}: joint names must be strings, got "
                         f"{names!r}")
    seen: set[str] = set()
    for name in names:
        if name in seen:
            return Rejection(Cause.DUPLICATE_JOINT, f"{where}: joint {name!r} appears twice")
        seen.add(name)
    unknown = [n for n in names if n not in joint_names]
    if unknown:
        return Rejection(Cause.UNKNOWN_JOINT, f"{where}: unknown joint {unknown[0]!r}; "
                         f"expected {list(joint_names)}")
    missing = [n for n in joint_names if n not in seen]
    if missing:
        return Rejection(Cause.MISSING_JOINT, f"{where}: joint {missing[0]!r} missing")
    return np.array([names.index(n) for n in joint_names], dtype=np.intp)


def validate_joint_state(names: Sequence[str], stamp_ns: int, position: Sequence[float],
                         velocity: Sequence[float], effort: Sequence[float],
                         joint_names: Sequence[str], last_stamp_ns: int | None = None,
                         where: str = "/joint_states") -> JointSample | Rejection:
    """A JointState: every configured joint exactly once (any order: reordered), position and
    velocity one finite value per name, effort empty or one finite value per name, stamp >= 0
    and strictly after ``last_stamp_ns`` (the last accepted stamp)."""
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)) \
            or stamp_ns < 0:
        return Rejection(Cause.BAD_STAMP, f"{where}: stamp {stamp_ns!r} is not a time >= 0 ns")
    if last_stamp_ns is not None and stamp_ns <= last_stamp_ns:
        return Rejection(Cause.NON_MONOTONIC_STAMP, f"{where}: stamp {int(stamp_ns)} ns is not "
                         f"after the previous {int(last_stamp_ns)} ns")
    order = joint_order(names, joint_names, where)
    if isinstance(order, Rejection):
        return order
    n = len(order)
    arrays: dict[str, np.ndarray | None] = {}
    for what, values, optional in (("position", position, False), ("velocity", velocity, False),
                                   ("effort", effort, True)):
        array = _numbers(values, what, where)
        if isinstance(array, Rejection):
            return array
        if optional and array.size == 0:
            arrays[what] = None
            continue
        if array.shape != (n,):
            return Rejection(Cause.WRONG_LENGTH, f"{where}: {what} has {array.size} values for "
                             f"{n} joint names")
        arrays[what] = array[order]
    pos, vel = arrays["position"], arrays["velocity"]
    assert pos is not None and vel is not None
    return JointSample(int(stamp_ns), pos, vel, arrays["effort"])


def validate_effort_command(values: Sequence[float], effort_limit: Sequence[float],
                            where: str = "/effort_controller/commands") -> np.ndarray | Rejection:
    """An effort command: one finite value per joint, each within +-effort_limit."""
    limit = np.asarray(effort_limit, dtype=float)
    array = _numbers(values, "effort", where)
    if isinstance(array, Rejection):
        return array
    if array.shape != limit.shape:
        return Rejection(Cause.WRONG_LENGTH, f"{where}: {array.size} efforts for "
                         f"{limit.size} joints")
    over = np.flatnonzero(np.abs(array) > limit)
    if over.size:
        j = int(over[0])
        return Rejection(Cause.OUT_OF_LIMIT, f"{where}: joint {j + 1} effort {array[j]!r} "
                         f"exceeds the limit {limit[j]!r} N m")
    return array


def validate_feedforward(names: Sequence[str], times_ns: Sequence[int],
                         position: Any, velocity: Any, feedforward: Any,
                         joint_names: Sequence[str], samples: int, period_ns: int,
                         feedforward_limit: Sequence[float] | None = None,
                         where: str = "/ilc/feedforward", joint_force: Any = None,
                         effort_limit: Sequence[float] | None = None
                         ) -> FeedforwardProfile | Rejection:
    """A feed-forward profile (JointTrajectory points: positions, velocities, accelerations
    = u_ff, effort = the identified joint forces or empty in every point): ``samples`` points
    at times i * period_ns, one finite value per joint name in each array (reordered to the
    configured order), |u_ff| within ``feedforward_limit`` (0 or None: unbounded), |effort|
    within ``effort_limit``. Over 10 parameters because it takes the message's fields and the
    configured values they are checked against one by one, as the controller node reads them,
    so it stays free of message types (the node translates, this module checks)."""
    order = joint_order(names, joint_names, where)
    if isinstance(order, Rejection):
        return order
    times = list(times_ns)
    if len(times) != samples:
        return Rejection(Cause.WRONG_LENGTH, f"{where}: {len(times)} points, expected "
                         f"{samples}")
    expected = [i * period_ns for i in range(samples)]
    if times != expected:
        i = next(i for i, (a, b) in enumerate(zip(times, expected, strict=True)) if a != b)
        return Rejection(Cause.WRONG_TIMES, f"{where}: point {i} at {times[i]!r} ns, expected "
                         f"{expected[i]} ns")
    out: list[np.ndarray] = []
    arrays = [("positions", position), ("velocities", velocity), ("accelerations", feedforward)]
    forces = None if joint_force is None else list(joint_force)  # rows converted below
    if forces is not None and all(len(row) == 0 for row in forces):
        forces = None
    if forces is not None:
        arrays.append(("effort", forces))
    for what, values in arrays:
        try:
            rows = [list(row) for row in values]
        except TypeError:
            return Rejection(Cause.NOT_NUMERIC, f"{where}: {what} is not a list of points")
        if len(rows) != samples or any(len(r) != len(order) for r in rows):
            bad = next((i for i, r in enumerate(rows) if len(r) != len(order)), len(rows))
            return Rejection(Cause.WRONG_LENGTH, f"{where}: {what} of point {bad} does not have "
                             f"one value per joint name ({len(order)})")
        array = _numbers(rows, what, where)
        if isinstance(array, Rejection):
            return array
        out.append(np.ascontiguousarray(array.reshape(samples, len(order))[:, order]))
    if feedforward_limit is not None:
        limit = np.asarray(feedforward_limit, dtype=float)
        limit = np.where(limit > 0.0, limit, np.inf)
        over = np.argwhere(np.abs(out[2]) > limit)
        if over.size:
            i, j = (int(x) for x in over[0])
            return Rejection(Cause.OUT_OF_LIMIT, f"{where}: u_ff of joint {j + 1} at point {i} "
                             f"is {out[2][i, j]!r}, beyond the limit {limit[j]!r}")
    if forces is not None and effort_limit is not None:
        bound = np.asarray(effort_limit, dtype=float)
        over = np.argwhere(np.abs(out[3]) > bound)
        if over.size:
            i, j = (int(x) for x in over[0])
            return Rejection(Cause.OUT_OF_LIMIT, f"{where}: the joint force of joint {j + 1} at "
                             f"point {i} is {out[3][i, j]!r}, beyond the effort limit "
                             f"{bound[j]!r}")
    return FeedforwardProfile(out[0], out[1], out[2], out[3] if forces is not None else None)


def check_feedforward_array(feedforward: np.ndarray, shape: tuple[int, ...],
                            where: str = "feed-forward") -> np.ndarray | Rejection:
    """An in-memory feed-forward (what a law returned): the expected shape and finite."""
    array = _numbers(feedforward, "u_ff", where)
    if isinstance(array, Rejection):
        return array
    if array.shape != tuple(shape):
        return Rejection(Cause.WRONG_LENGTH, f"{where}: shape {array.shape}, expected {shape}")
    return array


class LogOnce:
    """Counts rejections per cause; :meth:`record` says when a cause is new (log it then).

    ``counts`` holds every cause seen and how often; ``last`` its latest message, so a periodic
    diagnostics status can report both without flooding the log.
    """

    def __init__(self) -> None:
        self.counts: dict[Cause, int] = {}
        self.last: dict[Cause, str] = {}

    def record(self, rejection: Rejection) -> bool:
        """Count ``rejection``; True the first time its cause is seen."""
        first = rejection.cause not in self.counts
        self.counts[rejection.cause] = self.counts.get(rejection.cause, 0) + 1
        self.last[rejection.cause] = rejection.message
        return first

    @property
    def total(self) -> int:
        """All rejections counted."""
        return sum(self.counts.values())

    def as_values(self) -> list[tuple[str, str]]:
        """Key-values for a diagnostic status: ``rejected/<cause>`` = count."""
        return [(f"rejected/{c.value}", str(n)) for c, n in sorted(
            self.counts.items(), key=lambda item: item[0].value)]
