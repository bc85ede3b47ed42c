"""Diagnostics and message fields every node fills the same way: a DiagnosticStatus with string
key-values, a stamped DiagnosticArray, float64[] fields, stamps as nanoseconds."""

from __future__ import annotations

import array
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node


def status(name: str, message: str, values: Iterable[tuple[str, str]] = (),
           level: bytes = DiagnosticStatus.OK, hardware_id: str = "") -> DiagnosticStatus:
    """One diagnostic status with string key-values."""
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=v) for k, v in values])


def diagnostic_array(node: Node, statuses: Sequence[DiagnosticStatus],
                     stamp_ns: int | None = None) -> DiagnosticArray:
    """A DiagnosticArray stamped ``stamp_ns`` (default: the node's clock)."""
    msg = DiagnosticArray(status=list(statuses))
    if stamp_ns is None:
        msg.header.stamp = node.get_clock().now().to_msg()
    else:
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return msg


def values_of(item: DiagnosticStatus) -> dict[str, str]:
    """The key-values of a diagnostic status as a dict."""
    return {kv.key: kv.value for kv in item.values}


def doubles(values: np.ndarray) -> array.array[float]:
    """A float64[] message field from an array, without a per-element Python loop."""
    return array.array("d", np.ascontiguousarray(values, dtype=float).tobytes())


def stamp_ns(stamp: Any) -> int:
    """A builtin_interfaces/Time as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
