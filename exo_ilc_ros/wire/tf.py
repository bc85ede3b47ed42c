"""CDR of ``tf2_msgs/msg/TFMessage`` (what /tf carries), written directly: the live view sends
one per joint sample, and the general serialisers cost more than the rest of its work.
Checked against rosbags' deserialiser in ``test/test_live.py``."""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

from .cdr import HEADER

TF = "/tf"
TF_TYPE = "tf2_msgs/msg/TFMessage"
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_SEVEN = struct.Struct("<7d")


def _string(body: bytearray, text: str) -> None:
    body += b"\x00" * (-len(body) % 4)
    data = text.encode() + b"\x00"
    body += _U32.pack(len(data)) + data


def tf_message(stamp_ns: int,
               transforms: Sequence[tuple[str, str, np.ndarray, np.ndarray]]) -> bytes:
    """A TFMessage of (parent frame, child frame, translation xyz, quaternion xyzw), every
    transform stamped ``stamp_ns``."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    body = bytearray(_U32.pack(len(transforms)))
    for parent, child, translation, rotation in transforms:
        body += b"\x00" * (-len(body) % 4)
        body += _STAMP.pack(sec, nanosec)
        _string(body, parent)
        _string(body, child)
        body += b"\x00" * (-len(body) % 8)
        body += _SEVEN.pack(*(float(x) for x in translation), *(float(x) for x in rotation))
    return HEADER + bytes(body)
