"""Who may publish what the nodes act on: the rule, ROS-free (``nodes/sender_check.py`` binds it).

In lock-step a plant cannot tell a command from its controller by its content: one well-formed
``Float64MultiArray`` from a forgotten teleop once changed every later trial. So every input
the loop acts on names the node that must have sent it (:data:`PUBLISHER_OF`, the contract),
and each message is admitted by the GID of the DDS writer that sent it (taken with the
message, ``rmw_message_info_t.publisher_gid``):

* The **trusted** publisher of a topic is the only publisher of the contract's node on it
  (fully qualified name, in the subscriber's namespace), as the ROS graph lists it
  (``get_publishers_info_by_topic``). Once trusted, it stays trusted while it is in the graph
  (a second node that takes the same name later does not take over; after a restart the new
  one is trusted). Two publishers of that name at once, none trusted before: neither is
  trusted (ambiguous), and nothing on the topic is admitted.
* Every message from any other publisher is **refused**: never applied, counted per sending
  node. A message from a writer the last census did not list is looked up again once (the
  graph may lag the first message by microseconds), then refused as unknown.
* **More than one publisher** on the topic, or messages refused, is a fault: ERROR on
  ``/diagnostics`` while another publisher is there, WARN with the counts afterwards.

``/diagnostics`` is shared by design; there a status named ``<node>/...`` that the supervisor
acts on (the controller's acknowledgement and ``done``, the recorder's ``trials_filed``) is
admitted only from the node it names (:func:`status_owner`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from . import topics

CONTROLLER = "computed_torque_controller"
PLANT = "plant_simulator"
SUPERVISOR = "ilc_supervisor"
RECORDER = "bag_recorder"

PUBLISHER_OF: dict[str, str] = {
    topics.EFFORT_COMMANDS: CONTROLLER,
    topics.JOINT_STATES: PLANT,
    topics.TRUE_JOINT_STATES: PLANT,
    topics.FEEDFORWARD: SUPERVISOR,
    **{topic: PLANT for topic in topics.CUFF_WRENCHES},
}
"""Topic -> the name of the one node whose messages on it are acted on."""

UNNAMED = "_NODE_NAME_UNKNOWN_"
"""What the ROS graph gives as the node name of a writer whose node it does not know yet."""

TRUSTED = "trusted"
REFUSED = "refused"
UNKNOWN = "unknown"
""":meth:`PublisherCheck.admit`'s answers."""


@dataclass(frozen=True)
class Endpoint:
    """A publisher in the ROS graph: its node's fully qualified name and its writer's GID."""

    node: str
    gid: bytes


def qualified(namespace: str, name: str) -> str:
    """``/ns/name`` from a namespace (``/`` or ``/ns``) and a node name."""
    return f"{namespace.rstrip('/')}/{name}"


class PublisherCheck:
    """The publishers of one topic and which one is trusted; counts what it refused."""

    def __init__(self, topic: str, trusted_node: str) -> None:
        self.topic = topic
        self.trusted_node = trusted_node
        """Fully qualified name of the node whose publisher is trusted."""
        self.trusted_gid: bytes | None = None
        self.known: dict[bytes, str] = {}
        """GID -> node of every publisher in the last census."""
        self.refused: dict[str, int] = {}
        """Sending node (or ``unknown``) -> messages refused."""

    def set_publishers(self, endpoints: Iterable[Endpoint]) -> None:
        """The graph's publishers on the topic now. A writer whose node the graph cannot name
        yet (``_NODE_NAME_UNKNOWN_``: its participant's ROS discovery data has not arrived) is
        left out, not judged: its messages stay :data:`UNKNOWN`, so each one looks at the graph
        again until it names the node (a trusted node's first messages are refused, never all
        of them)."""
        self.known = {e.gid: e.node for e in endpoints if UNNAMED not in e.node}
        if self.trusted_gid not in self.known:
            self.trusted_gid = None
            candidates = [gid for gid, node in self.known.items() if node == self.trusted_node]
            if len(candidates) == 1:
                self.trusted_gid = candidates[0]

    def admit(self, gid: bytes) -> str:
        """:data:`TRUSTED`, :data:`REFUSED` (counted), or :data:`UNKNOWN` (not in the last
        census: take a census, then :meth:`admit_after_census`)."""
        if gid == self.trusted_gid:
            return TRUSTED
        node = self.known.get(gid)
        if node is None:
            return UNKNOWN
        self.refused[node] = self.refused.get(node, 0) + 1
        return REFUSED

    def admit_after_census(self, gid: bytes) -> bool:
        """A message from a writer the census had not listed, after a new census: True if it
        is the trusted one; otherwise refused and counted (as ``unknown`` if still unlisted)."""
        verdict = self.admit(gid)
        if verdict == UNKNOWN:
            self.refused[UNKNOWN] = self.refused.get(UNKNOWN, 0) + 1
        return verdict == TRUSTED

    @property
    def others(self) -> list[str]:
        """Nodes of the publishers other than the trusted one, in the last census."""
        return sorted(node for gid, node in self.known.items() if gid != self.trusted_gid)

    def fault(self) -> tuple[int, str]:
        """(0 OK, 1 WARN, 2 ERROR) and a sentence: ERROR while a publisher other than the
        trusted one is on the topic (or none is trusted though some publish), WARN once
        messages were refused."""
        refused = ", ".join(f"{node} x{n}" for node, n in sorted(self.refused.items()))
        tail = f"; refused: {refused}" if refused else ""
        if self.others:
            trusted = self.known.get(self.trusted_gid or b"", "none")
            return 2, (f"{len(self.known)} publishers on {self.topic} (trusted: {trusted}; "
                       f"others: {', '.join(self.others)}){tail}")
        if refused:
            return 1, f"messages on {self.topic} from other publishers{tail}"
        return 0, ""

    def as_values(self) -> list[tuple[str, str]]:
        """Key-values: ``publishers<topic>`` = count, ``refused<topic>/<node>`` = count."""
        return [(f"publishers{self.topic}", str(len(self.known))),
                *((f"refused{self.topic}/{node.lstrip('/')}", str(n))
                  for node, n in sorted(self.refused.items()))]


def status_owner(status_name: str, namespace: str = "/") -> str | None:
    """The node a ``/diagnostics`` status named ``<node>/<what>`` must come from (fully
    qualified), or None for a name without a node part."""
    node, sep, _ = status_name.partition("/")
    return qualified(namespace, node) if sep and node else None


SMALL_MESSAGE_BYTES = 65_536
"""Most bytes a /joint_states or effort command may have (the plant's JointState of 3 joints is
~150 bytes; 64 KiB leaves room for long names and frame ids, and refuses an array of 8192
doubles before it is decoded)."""
DIAGNOSTICS_BYTES = 1 << 20
"""Most bytes a /diagnostics message read by the supervisor may have."""


def max_bytes(topic: str, joints: int, samples: int) -> int:
    """Most bytes a message on ``topic`` may have for ``joints`` joints and trials of
    ``samples`` samples: a feed-forward profile is one point per sample (its time and four
    arrays of ``joints`` doubles, ~40 + 32 ``joints`` bytes), with twice that and 64 KiB to
    spare; the control loop's messages :data:`SMALL_MESSAGE_BYTES`."""
    if topic == topics.FEEDFORWARD:
        return 2 * samples * (64 + 32 * joints) + SMALL_MESSAGE_BYTES
    if topic == topics.DIAGNOSTICS:
        return DIAGNOSTICS_BYTES
    return SMALL_MESSAGE_BYTES
