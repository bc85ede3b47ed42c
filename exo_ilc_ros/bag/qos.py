"""The QoS each topic's publisher offers (one table for the recorder and the bag metadata)."""

from __future__ import annotations

from typing import Any

from .. import topics

RECORDER_DEPTH = 1000
"""Queue depth of the recorder's subscriptions: at 2 x 1 kHz, depth 10 dropped ~1 %."""

TRANSIENT_LOCAL_TOPICS = frozenset({topics.FEEDFORWARD})
"""Latched topics: a late subscriber still gets the last message."""


def offered_qos(topic: str) -> list[Any]:
    """rosbags ``Qos`` of ``topic``'s publisher (for ``metadata.yaml``; ``ros2 bag play``
    replays latched topics latched)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    durable = topic in TRANSIENT_LOCAL_TOPICS
    default = QosTime(0, 0)  # 0 = the RMW default (infinite) for deadline, lifespan, lease
    depth = 1 if durable or topic == topics.CLOCK else RECORDER_DEPTH
    return [Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE,
                QosDurability.TRANSIENT_LOCAL if durable else QosDurability.VOLATILE,
                default, default, QosLiveliness.AUTOMATIC, default, False)]
