"""Subscriptions that know who sent each message and refuse oversized ones before decoding.

rclpy (Jazzy) gives no publisher GID with a message: its ``MessageInfo`` holds the timestamps
and sequence numbers only, and the EventsExecutor cannot even call a callback that asks for it.
:class:`~exo_ilc_ros.nodes.raw_take.RawTaker` takes each message with its sender through rcl,
and refuses an oversized one from its byte size, never decoding it.

:class:`IdentifiedSubscription` is a :class:`rclpy.waitable.Waitable` around such a
subscription, so the EventsExecutor still wakes the node per message (~8 us more per message
than a plain raw subscription, measured in-process). :class:`TrustedInput` binds the rule of
:mod:`exo_ilc_ros.wire.publishers` to it: messages from the contract's publisher reach the
node's callback; others are refused and counted (per node, and as ``foreign_publisher`` or
their own bad-field cause on ``/diagnostics``).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.type_support import check_is_valid_msg_type
from rclpy.waitable import NumberOfEntities, Waitable

from ..core.loop.wire_input import Cause, Rejection, validate_effort_command
from ..wire import topics
from ..wire.cdr import CdrError, read_float64_array
from ..wire.publishers import (
    PUBLISHER_OF,
    TRUSTED,
    UNKNOWN,
    Endpoint,
    PublisherCheck,
    max_bytes,
    qualified,
    status_owner,
)
from .guard import Rejections
from .raw_take import RawTaker

TRUSTED_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL,
                                reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)
"""The readers of the control loop's samples and commands: keep all. A KEEP_LAST reader's
history is shared by every writer of the topic, so a burst of other publishers' messages
(refused on arrival, but only once taken) pushed the plant's sample out before the controller
took it, the lock-step loop waited for a command that never came, and the watchdog re-ran the
trial (seen in the fuzz test). Keeping all, a full reader makes the reliable writers resend
later instead: a flood delays, it does not delete."""
STATUS_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                               reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""The supervisor's reader of /diagnostics: 1000 deep, not the writers' 10, so a burst of
other messages cannot push the controller's ``done`` or acknowledgement out of the reader's
history before the supervisor takes it (a lost ``done`` costs the 30 s step timeout)."""
FEEDFORWARD_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                    reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""The controller's reader of /ilc/feedforward. Transient local like the writer (a late
controller still gets the last profile), but 100 deep: with the writer's depth of 1 on the
reader too, any message another publisher put on the topic after the profile and before the
controller took it replaced the profile in the reader's history, and the trial waited for an
acknowledgement that never came (issue 13's stalls). Other publishers' messages are refused
on arrival; the depth only has to outlast a burst between two takes."""

CLASSIFY_EVERY_NS = 500_000
CLASSIFY_BURST = 50
"""Foreign messages are checked for their bad-field cause at most once per 0.5 ms per input on
average, in bursts of up to 50 (a token bucket; every one is counted per sender): checking
costs ~50-100 us, and a flood checked in full delayed the plant's samples behind it past the
controller's watchdog (fuzz test)."""
HANDLER_ERRORS_LOGGED = 3
"""Tracebacks logged per subscription for messages whose handler raised; later ones counted."""


_KEPT: list[IdentifiedSubscription] = []
"""Destroyed subscriptions whose rcl handles live on until the process ends."""


class IdentifiedSubscription(Waitable):
    """A raw subscription whose messages reach ``deliver(raw or None, length, gid)``, woken by
    any rclpy executor (the EventsExecutor included); ``raw`` is None for a message longer
    than ``max_bytes`` (not copied, not decoded)."""

    def __init__(self, node: Node, msg_type: Any, topic: str, qos: QoSProfile,
                 deliver: Callable[[bytes | None, int, bytes], None],
                 max_bytes: int | None = None) -> None:
        super().__init__(node.default_callback_group)
        check_is_valid_msg_type(msg_type)
        with node.handle:
            self.handle = _rclpy.Subscription(node.handle, msg_type, topic,
                                              qos.get_c_qos_profile())
        self.node = node
        self.topic = topic
        self.taker = RawTaker(self.handle, max_bytes)
        self.deliver = deliver
        self.errors = 0
        """Messages whose handler raised (dropped; see :meth:`execute`)."""
        self._index = 0
        node.add_waitable(self)

    def get_publisher_count(self) -> int:
        """Publishers matched (any sender)."""
        with self.handle:
            return int(self.handle.get_publisher_count())

    # Waitable
    def __enter__(self) -> None:
        """An executor that registered this waitable holds the rcl subscription in use, so
        :meth:`destroy` defers freeing it until the executor let go (as for rclpy's own)."""
        self.handle.__enter__()

    def __exit__(self, kind: Any, value: Any, trace: Any) -> None:
        self.handle.__exit__(kind, value, trace)

    def is_ready(self, wait_set: Any) -> bool:
        return bool(wait_set.is_ready("subscription", self._index))

    def take_data(self) -> tuple[bytes | None, int, bytes, int] | None:
        return self.taker.take()

    async def execute(self, taken: tuple[bytes | None, int, bytes, int] | None) -> None:
        """Deliver a taken message. Nothing may escape: Jazzy's EventsExecutor segfaults on an
        exception raised in a waitable's task (ros2/rclpy#1641; reproduced here, and a plant
        died so under the fuzz test), so an error of ours on some input costs that message,
        is logged with its traceback (the first few) and counted (``handler_errors``)."""
        if taken is None:
            return
        try:
            self.deliver(taken[0], taken[1], taken[2])
        except Exception:
            self.errors += 1
            if self.errors <= HANDLER_ERRORS_LOGGED:
                self.node.get_logger().error(
                    f"{self.topic}: a message ({taken[1]} bytes) raised in its handler and was "
                    f"dropped (the node keeps running; counted as handler_errors):\n"
                    f"{traceback.format_exc()}")

    def get_num_entities(self) -> NumberOfEntities:
        return NumberOfEntities(1)

    def add_to_wait_set(self, wait_set: Any) -> None:
        self._index = wait_set.add_subscription(self.handle)

    def destroy(self) -> None:
        """Leave the node; nothing more is taken. The rcl subscription itself is kept until the
        process ends: the EventsExecutor may still run a wake-up it queued for it (freeing it
        earlier crashed a container whose recorder drains on after the supervisor is gone)."""
        if self in self.node.waitables:
            self.node.remove_waitable(self)
        self.taker.closed = True
        _KEPT.append(self)


def refresh_publishers(node: Node, check: PublisherCheck) -> None:
    """The graph's publishers on ``check.topic`` into ``check``."""
    check.set_publishers(Endpoint(qualified(info.node_namespace, info.node_name),
                          bytes(info.endpoint_gid))
                 for info in node.get_publishers_info_by_topic(check.topic))


class Admission:
    """The rule of :mod:`exo_ilc_ros.wire.publishers` for one input topic of a node: a
    message of at most ``max_bytes`` from the contract's publisher is admitted; an oversized
    one is refused (``oversized``) whoever sent it; one from another publisher is refused and
    counted per sender, and, when ``classify`` is given, checked like a message of the trusted
    one (``classify(raw)`` counts its bad-field cause and returns True if it had none) so the
    counts on /diagnostics say what it was; a well-formed foreign message counts as
    ``foreign_publisher``."""

    def __init__(self, node: Node, topic: str, rejections: Rejections, max_bytes: int,
                 classify: Callable[[bytes], bool] | None = None,
                 trusted: str | None = None) -> None:
        self.node = node
        self.rejections = rejections
        self.classify = classify
        self.max_bytes = max_bytes
        self.check = PublisherCheck(topic, qualified(node.get_namespace(),
                                                     trusted or PUBLISHER_OF[topic]))
        self._tokens = float(CLASSIFY_BURST)
        self._tokens_ns = time.monotonic_ns()
        self.refresh_publishers()

    def refresh_publishers(self) -> None:
        """Look at the graph again (every health report, and for an unlisted sender)."""
        refresh_publishers(self.node, self.check)

    def trusted_known(self) -> bool:
        """The contract's publisher is in the graph, after a fresh census (a trial starts only
        then: its first message is not refused as coming from a writer the graph did not list
        yet)."""
        self.refresh_publishers()
        return self.check.trusted_gid is not None

    def __call__(self, raw: bytes | None, length: int, gid: bytes) -> bool:
        """Size, then sender, then (for a foreign message) its fields: True to act on it."""
        topic = self.check.topic
        if raw is None or length > self.max_bytes:
            self.rejections.reject_cause(Cause.OVERSIZED, f"{topic}: {length} bytes, more "
                                         f"than the {self.max_bytes} a message may have")
            return False
        verdict = self.check.admit(gid)
        if verdict == TRUSTED:
            return True
        if verdict == UNKNOWN:
            self.refresh_publishers()
            if self.check.admit_after_census(gid):
                return True
        now = time.monotonic_ns()
        self._tokens = min(float(CLASSIFY_BURST),
                           self._tokens + (now - self._tokens_ns) / CLASSIFY_EVERY_NS)
        self._tokens_ns = now
        if self._tokens < 1.0:
            return False  # a flood: counted per sender only, the loop's messages go first
        self._tokens -= 1.0
        if self.classify is None or self.classify(raw):
            sender = self.check.known.get(gid)
            if sender is None:
                self.rejections.reject_cause(
                    Cause.UNLISTED_PUBLISHER, f"{topic}: a message from a writer the ROS graph "
                    "does not list yet (discovery still running: usual for a publisher's first "
                    f"messages at start-up); only {self.check.trusted_node}'s are acted on")
            else:
                self.rejections.reject_cause(
                    Cause.FOREIGN_PUBLISHER, f"{topic}: a message from {sender}; only "
                    f"{self.check.trusted_node} may publish here")
        return False

    def admit_raw(self, raw: bytes, gid: bytes) -> bool:
        """:meth:`__call__` for bytes already taken (an :class:`common.Inbox`)."""
        return self(raw, len(raw), gid)

    def health(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        """A :class:`guard.Health` check: ERROR while another publisher is on the topic."""
        self.refresh_publishers()
        level, reason = self.check.fault()
        levels = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR)
        return levels[level], reason, self.check.as_values()


class TrustedInput(Admission):
    """A subscription whose messages reach ``callback(raw)`` only when :class:`Admission`
    admits them."""

    def __init__(self, node: Node, msg_type: Any, topic: str, qos: QoSProfile,
                 callback: Callable[[bytes], None], rejections: Rejections, max_bytes: int,
                 classify: Callable[[bytes], bool] | None = None,
                 trusted: str | None = None) -> None:
        super().__init__(node, topic, rejections, max_bytes, classify, trusted)
        self.callback = callback
        self.subscription = IdentifiedSubscription(node, msg_type, topic, qos, self.on_message,
                                                   max_bytes)

    def get_publisher_count(self) -> int:
        """Publishers matched (any sender)."""
        return self.subscription.get_publisher_count()

    def health(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        """:meth:`Admission.health`, and ERROR once a message's handler raised (a bug: the
        message was dropped, the node kept running)."""
        level, reason, values = super().health()
        errors = self.subscription.errors
        if not errors:
            return level, reason, values
        dropped = f"{errors} message(s) on {self.check.topic} dropped: their handler raised " \
            "(see the log)"
        return DiagnosticStatus.ERROR, "; ".join(r for r in (reason, dropped) if r), \
            [*values, (f"handler_errors{self.check.topic}", str(errors))]

    def on_message(self, raw: bytes | None, length: int, gid: bytes) -> None:
        """The callback, for an admitted message."""
        if self(raw, length, gid):
            assert raw is not None
            self.callback(raw)

    def destroy(self) -> None:
        """Free the subscription."""
        self.subscription.destroy()


def effort_classifier(rejections: Rejections, joints: int) -> Callable[[bytes], bool]:
    """``classify`` for effort commands: decodable, one finite value per joint."""

    unbounded = [float("inf")] * joints

    def classify(raw: bytes) -> bool:
        try:
            effort = read_float64_array(raw)
        except CdrError as exc:
            rejections.reject_cause(Cause.NOT_NUMERIC, f"effort command: undecodable: {exc}")
            return False
        checked = validate_effort_command(effort.tolist(), unbounded)
        if isinstance(checked, Rejection):
            rejections.reject(checked)
            return False
        return True
    return classify


def gate_classifier(gate: Any) -> Callable[[bytes], bool]:
    """``classify`` for /joint_states: a :class:`guard.JointStateGate` of its own, restarted
    for every message (a foreign message is judged alone: neither the trusted stream's stamps
    nor another foreign message's count), which counts the cause of a bad message."""
    def classify(raw: bytes) -> bool:
        gate.restart()
        return gate(raw) is not None
    return classify


def deserializing_callback(msg_type: Any, callback: Callable[[Any], None], rejections: Rejections,
            topic: str) -> Callable[[bytes], None]:
    """A raw callback that deserialises first; undecodable bytes are refused
    (``not_numeric``), never raised out of the executor."""
    from rclpy.serialization import deserialize_message

    def on_raw(raw: bytes) -> None:
        try:
            msg = deserialize_message(raw, msg_type)
        except Exception as exc:  # any bytes may come; rclpy raises various errors
            rejections.reject_cause(Cause.NOT_NUMERIC, f"{topic}: undecodable: {exc}")
            return
        callback(msg)
    return on_raw


def decodes(msg_type: Any, rejections: Rejections, topic: str) -> Callable[[bytes], bool]:
    """``classify`` for a deserialised topic: True if the bytes decode."""
    ok: list[bool] = []

    def note(msg: Any) -> None:
        ok.append(True)
    on_raw = deserializing_callback(msg_type, note, rejections, topic)

    def classify(raw: bytes) -> bool:
        ok.clear()
        on_raw(raw)
        return bool(ok)
    return classify


class StatusAdmission:
    """``/diagnostics`` for a node that acts on other nodes' statuses (an :class:`common.Inbox`
    ``admit`` rule): a message is admitted only if every status named ``<node>/...`` in it was
    sent by that node's publisher (a node publishes its own statuses); others are refused
    (``foreign_publisher``), as are oversized (``oversized``) and undecodable (``not_numeric``)
    ones.

    (Read through the inbox, not an :class:`IdentifiedSubscription`: a waitable on a node that
    leaves the EventsExecutor while the executor spins on for a draining recorder crashed the
    supervisor's container at shut-down.)"""

    def __init__(self, node: Node, rejections: Rejections) -> None:
        self.node = node
        self.rejections = rejections
        self.limit = max_bytes(topics.DIAGNOSTICS, 0, 0)
        self.check = PublisherCheck(topics.DIAGNOSTICS, "")

    def __call__(self, raw: bytes, gid: bytes) -> bool:
        """Size, then decode, then each named status against its sender."""
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.serialization import deserialize_message


        if len(raw) > self.limit:
            self.rejections.reject_cause(Cause.OVERSIZED, f"/diagnostics: {len(raw)} bytes, "
                                         f"more than {self.limit}")
            return False
        try:
            msg = deserialize_message(raw, DiagnosticArray)
        except Exception as exc:  # any bytes may come; rclpy raises various errors
            self.rejections.reject_cause(Cause.NOT_NUMERIC, f"/diagnostics: undecodable: {exc}")
            return False
        sender = self.check.known.get(gid)
        if sender is None:
            refresh_publishers(self.node, self.check)
            sender = self.check.known.get(gid, "")
        namespace = self.node.get_namespace()
        for item in msg.status:
            owner = status_owner(item.name, namespace)
            if owner is not None and owner != sender:
                if sender:
                    self.rejections.reject_cause(
                        Cause.FOREIGN_PUBLISHER, f"/diagnostics: status {item.name!r} from "
                        f"{sender}, not {owner}")
                else:
                    self.rejections.reject_cause(
                        Cause.UNLISTED_PUBLISHER, f"/diagnostics: status {item.name!r} from a "
                        "writer the ROS graph does not list yet (discovery still running); "
                        f"acted on only from {owner}")
                return False
        return True
