"""The QoS each topic's publishers offer (one table for the recorder and the bag metadata).

:data:`OFFERED` mirrors the profiles the nodes publish with (``nodes/common.py``: SAMPLES_QOS,
LATCHED_QOS, CLOCK_QOS, EVENTS_QOS, DIAGNOSTICS_QOS, and rclpy's parameter-events profile); a
graph test compares it with what the running graph offers. A bag records it per topic as
``offered_qos_profiles``, from which ``ros2 bag play`` offers the same reliability and
durability again: a late subscriber of a replayed bag gets the trial events, summaries and
health it would have got from the graph.
"""

from __future__ import annotations

from typing import Any

from . import topics

OFFERED_DEPTH = 1000
"""History depth of the graph's sample and event publishers (``SAMPLES_QOS``, ``EVENTS_QOS``)."""

TF_DEPTH = 100
"""History depth of /tf as tf2's TransformBroadcaster offers it."""

DIAGNOSTICS_DEPTH = 10
"""History depth of the nodes' /diagnostics publishers (``DIAGNOSTICS_QOS``)."""

RECORDER_DEPTH = 10000
"""Queue depth of the recorder's subscriptions, drained every 10 ms (at 2 x 1 kHz, depth 10
dropped ~1 % when read per message; 10 000 leaves seconds of slack)."""

TRANSIENT_LOCAL_TOPICS = frozenset({topics.FEEDFORWARD, topics.TRIAL_EVENTS,
                                    topics.TRIAL_SUMMARY, topics.TRIAL_METRICS,
                                    topics.DIAGNOSTICS, topics.PERSON_DESCRIPTION})
"""Topics the recorder subscribes to transient local: those whose publishers keep a history
for late joiners (see :data:`OFFERED`). A recorder matched after a message was sent still gets
it from that history: the latched feed-forward (depth 1), every trial event, summary and
metrics message (depth 1000) and each node's last 10 /diagnostics (its health from before the
recorder was up included), so the bag holds every message the nodes published."""

VOLATILE, TRANSIENT_LOCAL = "volatile", "transient_local"

OFFERED: dict[str, tuple[tuple[str, int], ...]] = {
    topics.JOINT_STATES: ((VOLATILE, OFFERED_DEPTH),),
    topics.CLOCK: ((VOLATILE, OFFERED_DEPTH),),
    topics.EFFORT_COMMANDS: ((VOLATILE, OFFERED_DEPTH),),
    topics.FEEDFORWARD: ((TRANSIENT_LOCAL, 1),),
    topics.TRIAL_EVENTS: ((TRANSIENT_LOCAL, OFFERED_DEPTH),),
    topics.TRIAL_SUMMARY: ((TRANSIENT_LOCAL, OFFERED_DEPTH),),
    topics.TRIAL_METRICS: ((TRANSIENT_LOCAL, OFFERED_DEPTH),),
    topics.DIAGNOSTICS: ((TRANSIENT_LOCAL, DIAGNOSTICS_DEPTH), (TRANSIENT_LOCAL, OFFERED_DEPTH)),
    topics.PARAMETER_EVENTS: ((VOLATILE, OFFERED_DEPTH),),
    topics.ROBOT_DESCRIPTION: ((TRANSIENT_LOCAL, 1),),
    topics.REFERENCE_DESCRIPTION: ((TRANSIENT_LOCAL, 1),),
    topics.TF: ((VOLATILE, TF_DEPTH),),
    topics.PERSON_DESCRIPTION: ((TRANSIENT_LOCAL, 1),),
}
"""Per topic, the (durability, depth) of each distinct publisher profile, all reliable and
keep-last: /diagnostics has the nodes' health (depth 10) and bag_recorder's status (depth
1000, ``EVENTS_QOS``); /parameter_events is rclpy's default profile for it. The view's topics
(:data:`topics.VIEW_TYPES`, written by the bag writers, no node publishes them) as ROS
publishes them: the URDFs as robot_state_publisher (transient local, depth 1), /tf as tf2's
TransformBroadcaster (volatile, depth 100), so ``ros2 bag play`` offers them so too."""


def offered_qos(topic: str) -> list[Any]:
    """rosbags ``Qos`` of ``topic``'s publishers (for ``metadata.yaml`` and the MCAP channel;
    ``ros2 bag play`` replays transient-local topics transient local)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    default = QosTime(0, 0)  # 0 = the RMW default (infinite) for deadline, lifespan, lease
    durability = {VOLATILE: QosDurability.VOLATILE,
                  TRANSIENT_LOCAL: QosDurability.TRANSIENT_LOCAL}
    return [Qos(QosHistory.KEEP_LAST, depth, QosReliability.RELIABLE, durability[kind],
                default, default, QosLiveliness.AUTOMATIC, default, False)
            for kind, depth in OFFERED.get(topic, ((VOLATILE, OFFERED_DEPTH),))]
