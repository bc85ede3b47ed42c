"""CDR of ``tf2_msgs/msg/TFMessage`` (what /tf carries), written directly: the live view sends
one per joint sample, and the general serialisers cost more than the rest of its work.
Checked against rosbags' deserialiser in ``test/test_live.py``."""

from __future__ import annotations

import struct
from collections.abc import Sequence

from .cdr import HEADER
from .topics import TF, VIEW_TYPES

TF_TYPE = VIEW_TYPES[TF]
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_SEVEN = struct.Struct("<7d")


def _string(parts: list[bytes], offset: int, text: str) -> int:
    """Append a CDR string at body ``offset``; returns the offset after it."""
    pad = -offset % 4
    data = text.encode() + b"\x00"
    parts.append(b"\x00" * pad + _U32.pack(len(data)) + data)
    return offset + pad + 4 + len(data)


def tf_message(stamp_ns: int, transforms: Sequence[tuple[str, str, Sequence[float],
                                                         Sequence[float]]]) -> bytes:
    """A TFMessage of (parent frame, child frame, translation xyz, quaternion xyzw), every
    transform stamped ``stamp_ns``."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    stamp = _STAMP.pack(sec, nanosec)
    parts = [_U32.pack(len(transforms))]
    offset = 4
    for parent, child, translation, rotation in transforms:
        pad = -offset % 4
        parts.append(b"\x00" * pad + stamp)
        offset += pad + 8
        offset = _string(parts, offset, parent)
        offset = _string(parts, offset, child)
        pad = -offset % 8
        tx, ty, tz = translation
        rx, ry, rz, rw = rotation
        parts.append(b"\x00" * pad + _SEVEN.pack(tx, ty, tz, rx, ry, rz, rw))
        offset += pad + 56
    return HEADER + b"".join(parts)
