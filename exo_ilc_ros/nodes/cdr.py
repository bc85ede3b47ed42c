"""CDR (little-endian XCDR1, what rmw_fastrtps puts on the wire) for the two messages of the
control loop, so the hot callbacks skip rclpy's Python message objects.

``JointStateWriter`` fills a preallocated JointState image (stamp, position, velocity,
effort) in place; ``read_joint_state`` and ``read_float64_array`` decode the raw bytes a
``raw=True`` subscription delivers, for any publisher (names, frame_id and layout of any
length). Checked against rclpy's own (de)serialisation in ``test/test_cdr.py``.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

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


def read_joint_state_full(raw: bytes
                          ) -> tuple[int, list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(stamp in ns, names, position, velocity, effort) of a serialised sensor_msgs/JointState
    (the slow path for messages of another layout than the plant's)."""
    try:
        _check_header(raw)
        sec, nanosec = STAMP.unpack_from(raw, 4)
        offset = _skip_string(raw, 8)
        (count,) = _U32.unpack_from(raw, 4 + _align(offset, 4))
        offset = _align(offset, 4) + 4
        if count > len(raw):
            raise CdrError(f"{count} names in a message of {len(raw)} bytes")
        names = []
        for _ in range(count):
            start = _align(offset, 4)
            (length,) = _U32.unpack_from(raw, 4 + start)
            text = bytes(raw[4 + start + 4:4 + start + 4 + length])
            if len(text) != length:
                raise CdrError("name runs past the end of the message")
            names.append(text.rstrip(b"\x00").decode("utf-8", errors="replace"))
            offset = start + 4 + length
        position, offset = _doubles(raw, offset)
        velocity, offset = _doubles(raw, offset)
        effort, offset = _doubles(raw, offset)
    except struct.error as exc:
        raise CdrError(f"truncated JointState: {exc}") from None
    return sec * 1_000_000_000 + nanosec, names, position, velocity, effort
