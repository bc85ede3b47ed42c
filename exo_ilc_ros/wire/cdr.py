"""CDR (little-endian XCDR1, what rmw_fastrtps puts on the wire) of the control loop's two
messages: the fast paths the nodes, the recorder and the bag reader share.

``JointStateWriter`` fills a preallocated JointState image (stamp, position, velocity,
effort) in place; ``read_joint_state`` and ``read_float64_array`` decode the raw bytes a
``raw=True`` subscription delivers, for any publisher (names, frame_id and layout of any
length); ``joint_states`` decodes a whole recorded stream at once (messages of one layout as
rows of one array, ~20x faster than one by one); ``read_trajectory_positions`` reads the
positions of a feed-forward profile (the reference arm of the live view and the bags) as
strided rows. One walk over a JointState's fields
(``_names_span``, ``_doubles``) serves them all. Checked against rclpy's and rosbags' own
(de)serialisation in ``test/test_cdr.py`` and ``test/test_bag.py``.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .topics import JOINT_STATES, TYPES

HEADER = b"\x00\x01\x00\x00"
"""Encapsulation: CDR, little endian."""
_NO_DIMS = b"\x00\x00\x00\x00"
"""A Float64MultiArray layout without dims (what :func:`float64_array` writes)."""
_U32 = struct.Struct("<I")
STAMP = struct.Struct("<iI")
"""builtin_interfaces/Time (sec, nanosec), right after the encapsulation header in a
stamped message."""


class CdrError(ValueError):
    """The bytes are not a message of the expected layout."""


def _align(offset: int, size: int) -> int:
    """``offset`` (counted after the 4-byte encapsulation header) rounded up to ``size``."""
    return offset + (-offset % size)


class _Writer:
    def __init__(self) -> None:
        self.body = bytearray()

    def pad(self, size: int) -> None:
        self.body += b"\x00" * (-len(self.body) % size)

    def u32(self, value: int) -> None:
        self.pad(4)
        self.body += _U32.pack(value)

    def string(self, text: str) -> None:
        data = text.encode() + b"\x00"
        self.u32(len(data))
        self.body += data

    def doubles(self, count: int) -> int:
        """A sequence of ``count`` zero doubles; returns the offset of the first."""
        self.u32(count)
        self.pad(8)
        offset = len(self.body)
        self.body += b"\x00" * (8 * count)
        return offset


class JointStateWriter:
    """A sensor_msgs/JointState image with fixed names; :meth:`write` fills it in place."""

    def __init__(self, names: Sequence[str], frame_id: str = "") -> None:
        w = _Writer()
        w.body += b"\x00" * 8  # stamp
        w.string(frame_id)
        w.u32(len(names))
        for name in names:
            w.string(name)
        n = len(names)
        offsets = [w.doubles(n) for _ in range(3)]
        self._buffer = bytearray(HEADER + w.body)
        self._fields = [np.frombuffer(self._buffer, dtype="<f8", count=n, offset=4 + o)
                        for o in offsets]

    def write(self, stamp_ns: int, position: np.ndarray, velocity: np.ndarray,
              effort: np.ndarray) -> bytes:
        """The serialised message with this stamp and state."""
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        STAMP.pack_into(self._buffer, 4, sec, nanosec)
        self._fields[0][:] = position
        self._fields[1][:] = velocity
        self._fields[2][:] = effort
        return bytes(self._buffer)


def float64_array(values: np.ndarray) -> bytes:
    """A std_msgs/Float64MultiArray with an empty layout and ``values`` as data."""
    n = values.shape[0]
    # dim: count 0 (4 bytes), data_offset (4), data count (4), pad to 8 -> data at body 16
    return HEADER + struct.pack("<III", 0, 0, n) + b"\x00" * 4 + \
        np.ascontiguousarray(values, dtype="<f8").tobytes()


def _skip_string(raw: bytes, offset: int) -> int:
    offset = _align(offset, 4)
    (length,) = _U32.unpack_from(raw, 4 + offset)
    return offset + 4 + length


def _doubles(raw: bytes, offset: int) -> tuple[np.ndarray, int]:
    offset = _align(offset, 4)
    (count,) = _U32.unpack_from(raw, 4 + offset)
    offset = _align(offset + 4, 8) if count else offset + 4
    end = offset + 8 * count
    if 4 + end > len(raw):
        raise CdrError("sequence runs past the end of the message")
    return np.frombuffer(raw, dtype="<f8", count=count, offset=4 + offset), end


def _check_header(raw: bytes) -> None:
    if raw[:2] != HEADER[:2]:
        raise CdrError(f"not little-endian CDR (encapsulation {raw[:4]!r})")


def read_joint_state(raw: bytes) -> tuple[int, np.ndarray, np.ndarray]:
    """(stamp in ns, position, velocity) of a serialised sensor_msgs/JointState (read-only
    views into ``raw``)."""
    try:
        return _read_joint_state(raw)
    except struct.error as exc:
        raise CdrError(f"truncated JointState: {exc}") from None


def _names_span(raw: bytes) -> tuple[int, int]:
    """Body offsets of a serialised JointState's ``name`` sequence: its start (just past the
    frame_id) and its end (raises struct.error when truncated)."""
    _check_header(raw)
    start = _skip_string(raw, 8)  # past frame_id
    (count,) = _U32.unpack_from(raw, 4 + _align(start, 4))
    offset = _align(start, 4) + 4
    for _ in range(count):
        offset = _skip_string(raw, offset)
    return start, offset


def _read_joint_state(raw: bytes) -> tuple[int, np.ndarray, np.ndarray]:
    sec, nanosec = STAMP.unpack_from(raw, 4)
    position, offset = _doubles(raw, _names_span(raw)[1])
    velocity, offset = _doubles(raw, offset)
    return sec * 1_000_000_000 + nanosec, position, velocity


def joint_state_offsets(raw: bytes) -> tuple[int, int]:
    """Byte offsets (in ``raw``) of the first position and the first velocity of a serialised
    sensor_msgs/JointState."""
    try:
        position, offset = _doubles(raw, _names_span(raw)[1])
        velocity, end = _doubles(raw, offset)
    except struct.error as exc:
        raise CdrError(f"truncated JointState: {exc}") from None
    # _doubles returns the body offset just past the values; +4 skips the encapsulation.
    return 4 + offset - 8 * position.shape[0], 4 + end - 8 * velocity.shape[0]


def read_float64_array(raw: bytes) -> np.ndarray:
    """The data of a serialised std_msgs/Float64MultiArray (a read-only view into ``raw``)."""
    if raw[4:8] == _NO_DIMS and raw[:2] == HEADER[:2] and len(raw) > 20:
        # The common layout (no dims, as float64_array writes it): data at byte 20.
        (count,) = _U32.unpack_from(raw, 12)
        if len(raw) == 20 + 8 * count:
            return np.frombuffer(raw, dtype="<f8", count=count, offset=20)
    try:
        return _read_float64_array(raw)
    except struct.error as exc:
        raise CdrError(f"truncated Float64MultiArray: {exc}") from None


def _read_float64_array(raw: bytes) -> np.ndarray:
    _check_header(raw)
    (dims,) = _U32.unpack_from(raw, 4)
    offset = 4
    for _ in range(dims):
        offset = _skip_string(raw, offset)  # label
        offset = _align(offset, 4) + 8  # size, stride
    offset = _align(offset, 4) + 4  # data_offset
    data, _ = _doubles(raw, offset)
    return data


def names_segment(raw: bytes) -> bytes:
    """The bytes of a serialised JointState's ``name`` sequence (and the frame_id before it):
    equal segments mean equal names, so a node checks names once per layout."""
    try:
        start, end = _names_span(raw)
    except struct.error as exc:
        raise CdrError(f"truncated JointState: {exc}") from None
    return bytes(raw[4 + start:4 + end])


def _strings(raw: bytes, offset: int) -> tuple[list[str], int]:
    """A sequence of strings at body ``offset``, and the offset past it."""
    (count,) = _U32.unpack_from(raw, 4 + _align(offset, 4))
    offset = _align(offset, 4) + 4
    if count > len(raw):
        raise CdrError(f"{count} strings in a message of {len(raw)} bytes")
    names = []
    for _ in range(count):
        start = _align(offset, 4)
        (length,) = _U32.unpack_from(raw, 4 + start)
        text = bytes(raw[4 + start + 4:4 + start + 4 + length])
        if len(text) != length:
            raise CdrError("a string runs past the end of the message")
        names.append(text.rstrip(b"\x00").decode("utf-8", errors="replace"))
        offset = start + 4 + length
    return names, offset


def read_joint_state_full(raw: bytes
                          ) -> tuple[int, list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(stamp in ns, names, position, velocity, effort) of a serialised sensor_msgs/JointState
    (the slow path for messages of another layout than the plant's)."""
    try:
        _check_header(raw)
        sec, nanosec = STAMP.unpack_from(raw, 4)
        names, offset = _strings(raw, _skip_string(raw, 8))
        position, offset = _doubles(raw, offset)
        velocity, offset = _doubles(raw, offset)
        effort, offset = _doubles(raw, offset)
    except struct.error as exc:
        raise CdrError(f"truncated JointState: {exc}") from None
    return sec * 1_000_000_000 + nanosec, names, position, velocity, effort


@dataclass(frozen=True)
class _Point:
    """Where a JointTrajectoryPoint's fields sit (body offsets)."""

    counts: tuple[tuple[int, int], ...]
    """(offset, value) of its four sequence counts: positions, velocities, accelerations,
    effort."""
    positions: int
    """Offset of its first position."""
    width: int
    """How many positions."""
    end: int
    """Offset just past it (past time_from_start)."""


def _point(raw: bytes, offset: int) -> _Point:
    counts = []
    positions = width = 0
    for field in range(4):  # positions, velocities, accelerations, effort
        at = _align(offset, 4)
        values, offset = _doubles(raw, offset)
        counts.append((at, values.shape[0]))
        if field == 0:
            positions, width = offset - 8 * values.shape[0], values.shape[0]
    end = _align(offset, 4) + 8  # time_from_start (builtin_interfaces/Duration)
    if 4 + end > len(raw):
        raise CdrError("a trajectory point runs past the end of the message")
    return _Point(tuple(counts), positions, width, end)


def read_trajectory_positions(raw: bytes) -> tuple[int, list[str], np.ndarray]:
    """(header stamp in ns, joint_names, positions: one row per point) of a serialised
    trajectory_msgs/JointTrajectory (the live view's and the bags' reference arm, from
    ``/ilc/feedforward``). Points of one layout are read as strided rows (a 501-point profile
    in ~0.1 ms instead of ~15 ms through rosbags); CdrError if the points do not all hold as
    many positions."""
    try:
        return _read_trajectory_positions(raw)
    except struct.error as exc:
        raise CdrError(f"truncated JointTrajectory: {exc}") from None


def _read_trajectory_positions(raw: bytes) -> tuple[int, list[str], np.ndarray]:
    _check_header(raw)
    sec, nanosec = STAMP.unpack_from(raw, 4)
    names, offset = _strings(raw, _skip_string(raw, 8))
    offset = _align(offset, 4)
    (count,) = _U32.unpack_from(raw, 4 + offset)
    offset += 4
    if count > len(raw):
        raise CdrError(f"{count} points in a message of {len(raw)} bytes")
    blocks: list[np.ndarray] = []
    width: int | None = None
    done = 0
    while done < count:
        # The padding before a point's doubles depends on where it starts (mod 8), so the
        # layout repeats every one or two points: walk one period, then read its copies as
        # strided rows for as long as every count in them is the same.
        period = [_point(raw, offset)]
        if period[0].end % 8 != offset % 8 and done + 1 < count:
            second = _point(raw, period[0].end)
            if second.end % 8 == offset % 8:
                period.append(second)
        width = period[0].width if width is None else width
        if any(point.width != width for point in period):
            raise CdrError("trajectory points with different numbers of positions")
        k, stride = len(period), period[-1].end - offset
        repeats = 0
        if stride % 8 == 0:
            fits = min((count - done) // k, (len(raw) - 4 - offset) // stride)
            same = np.ones(fits, dtype=bool)
            for point in period:
                for at, value in point.counts:
                    same &= np.ndarray((fits,), "<u4", raw, 4 + at, (stride,)) == value
            repeats = fits if same.all() else int(np.argmin(same))
        if repeats:
            block = np.empty((repeats * k, width))
            for j, point in enumerate(period):
                block[j::k] = np.ndarray((repeats, width), "<f8", raw, 4 + point.positions,
                                         (stride, 8))
            offset, done = offset + repeats * stride, done + repeats * k
        else:  # this point's layout does not repeat: it alone
            block = np.ndarray((1, width), "<f8", raw, 4 + period[0].positions).copy()
            offset, done = period[0].end, done + 1
        blocks.append(block)
    positions = np.concatenate(blocks) if blocks else np.zeros((0, len(names)))
    return sec * 1_000_000_000 + nanosec, names, positions


@dataclass
class JointStates:
    """Every JointState of a stream, as arrays (NaN rows where a message lacked a field)."""

    stamps: np.ndarray
    """header.stamp in ns, (m,)"""
    names: list[str]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


@dataclass(frozen=True)
class _Rows:
    """Where a JointState's fields sit, for reading messages of its layout as table rows."""

    size: int
    names: tuple[int, int]
    """Byte span of frame_id and names: rows with other bytes there go the slow way."""
    arrays: tuple[int | None, int | None, int | None]
    """Byte offsets of position, velocity, effort data (None: empty)."""


def _rows(raw: bytes, joints: int) -> _Rows | None:
    """The layout of this JointState for row-wise reading, or None (other endianness, a
    position or velocity not of ``joints`` values)."""
    try:
        _, names_end = _names_span(raw)  # checks the encapsulation too
        offset = names_end
        arrays: list[int | None] = []
        for _ in range(3):
            values, offset = _doubles(raw, offset)
            if values.shape[0] not in (0, joints):
                return None
            arrays.append(4 + offset - 8 * joints if values.shape[0] else None)
    except (struct.error, CdrError):
        return None
    if 4 + offset != len(raw) or arrays[0] is None or arrays[1] is None:
        return None
    return _Rows(len(raw), (12, 4 + names_end), (arrays[0], arrays[1], arrays[2]))


def joint_states(raws: Sequence[bytes], decode: Callable[[bytes, str], Any],
                 joint_names: Sequence[str] = ()) -> JointStates:
    """Decode ``raws`` (all of one topic); messages with the first one's layout and names are
    read as rows of one array, any other through ``decode`` (rosbags' deserialiser);
    ``joint_names`` is used if the messages carry none."""
    msgtype = TYPES[JOINT_STATES]
    first = decode(raws[0], msgtype)
    names = [str(n) for n in first.name] or list(joint_names)
    joints = len(names) or len(first.position)
    m = len(raws)
    stamps = np.zeros(m, dtype=np.int64)
    out = [np.full((m, joints), np.nan) for _ in range(3)]
    layout = _rows(raws[0], joints)
    fast = np.zeros(m, dtype=bool)
    if layout is not None:
        fast = np.fromiter((len(r) == layout.size for r in raws), bool, m)
        rows = np.flatnonzero(fast)
        buffer = np.frombuffer(b"".join(raws[int(i)] for i in rows), dtype=np.uint8)
        table = buffer.reshape(len(rows), layout.size)
        a, b = layout.names
        same = (table[:, a:b] == table[0, a:b]).all(axis=1) & \
            (table[:, :2] == table[0, :2]).all(axis=1)
        fast[rows[~same]] = False
        rows, table = rows[same], table[same]
        sec = table[:, 4:8].copy().view("<i4")[:, 0].astype(np.int64)
        nanosec = table[:, 8:12].copy().view("<u4")[:, 0].astype(np.int64)
        stamps[rows] = sec * 1_000_000_000 + nanosec
        for target, start in zip(out, layout.arrays, strict=True):
            if start is not None:
                target[rows] = table[:, start:start + 8 * joints].copy().view("<f8")
    for i in np.flatnonzero(~fast):
        msg = decode(raws[int(i)], msgtype)
        stamps[i] = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        for target, values in zip(out, (msg.position, msg.velocity, msg.effort), strict=True):
            if len(values) == joints:
                target[i] = values
    return JointStates(stamps, names, out[0], out[1], out[2])
