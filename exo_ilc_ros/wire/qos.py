"""The QoS each topic's publisher offers (one table for the recorder and the bag metadata)."""

from __future__ import annotations

from typing import Any

from . import topics

OFFERED_DEPTH = 1000
"""History depth of the graph's sample and event publishers (``SAMPLES_QOS``, ``EVENTS_QOS``)."""

RECORDER_DEPTH = 10000
"""Queue depth of the recorder's subscriptions, drained every 10 ms (at 2 x 1 kHz, depth 10
dropped ~1 % when read per message; 10 000 leaves seconds of slack)."""

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
    depth = 1 if durable or topic == topics.CLOCK else OFFERED_DEPTH
    return [Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE,
                QosDurability.TRANSIENT_LOCAL if durable else QosDurability.VOLATILE,
                default, default, QosLiveliness.AUTOMATIC, default, False)]
