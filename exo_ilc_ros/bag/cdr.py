"""Decoding many ``sensor_msgs/JointState`` CDR messages at once.

Messages of one publisher have the same layout (same names, same array lengths), so their bytes
differ only in the stamp and the numbers: the field offsets are found once (in the first
message) and every message of that length is read as a row of one numpy array. Messages of
another length, or big-endian CDR, go through rosbags' decoder one by one. 20x faster than
decoding each message (75 000 joint states: 0.15 s instead of 3 s).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import topics

_CDR_LE = b"\x00\x01"


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
class _Layout:
    size: int
    stamp: int
    arrays: tuple[int | None, int | None, int | None]
    """Byte offsets of position, velocity, effort data (None: empty)."""


def _align(offset: int, size: int) -> int:
    """CDR alignment, relative to the end of the 4-byte encapsulation header."""
    body = offset - 4
    return 4 + (body + size - 1) // size * size


def _layout(raw: bytes, joints: int) -> _Layout | None:
    """Where the fields of this little-endian JointState are; None if it is not one we can
    read row-wise (other endianness, arrays of another length)."""
    if raw[:2] != _CDR_LE:
        return None
    try:
        offset = 4 + 8
        (length,) = struct.unpack_from("<I", raw, offset)
        offset += 4 + length
        offset = _align(offset, 4)
        (count,) = struct.unpack_from("<I", raw, offset)
        offset += 4
        for _ in range(count):
            offset = _align(offset, 4)
            (length,) = struct.unpack_from("<I", raw, offset)
            offset += 4 + length
        arrays: list[int | None] = []
        for _ in range(3):
            offset = _align(offset, 4)
            (count,) = struct.unpack_from("<I", raw, offset)
            offset += 4
            if count == 0:
                arrays.append(None)
                continue
            if count != joints:
                return None
            offset = _align(offset, 8)
            arrays.append(offset)
            offset += 8 * count
    except struct.error:
        return None
    if offset != len(raw) or arrays[0] is None or arrays[1] is None:
        return None
    return _Layout(len(raw), 4, (arrays[0], arrays[1], arrays[2]))


def joint_states(raws: Sequence[bytes], decode: Callable[[bytes, str], Any],
                 joint_names: Sequence[str] = ()) -> JointStates:
    """Decode ``raws`` (all of one topic); ``joint_names`` is used if the messages carry
    none."""
    msgtype = topics.TYPES[topics.JOINT_STATES]
    first = decode(raws[0], msgtype)
    names = [str(n) for n in first.name] or list(joint_names)
    joints = len(names) or len(first.position)
    m = len(raws)
    stamps = np.zeros(m, dtype=np.int64)
    out = [np.full((m, joints), np.nan) for _ in range(3)]
    layout = _layout(raws[0], joints)
    fast = np.zeros(m, dtype=bool)
    if layout is not None:
        fast = np.fromiter((len(r) == layout.size for r in raws), bool, m)
        rows = np.flatnonzero(fast)
        buffer = np.frombuffer(b"".join(raws[int(i)] for i in rows), dtype=np.uint8)
        table = buffer.reshape(len(rows), layout.size)
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
