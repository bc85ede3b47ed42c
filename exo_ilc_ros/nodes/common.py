"""Plumbing every node shares: schema parameters as ROS parameters, the set-parameters guard,
QoS profiles, diagnostics helpers and the spin loop."""

from __future__ import annotations

import json
import re
import signal
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, Protocol, runtime_checkable

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from ..core.errors import ExoIlcError
from ..wire import topics
from . import parameters, realtime
from .raw_take import RawTaker
from .sender_check import IdentifiedSubscription

RCLError = rclpy_implementation.RCLError

SAMPLES_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
"""/joint_states and the effort commands: reliable, deep enough that no sample of a trial is
lost even in real-time mode."""

LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""/ilc/feedforward: the last profile is delivered to late joiners."""

CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
"""/clock publisher: reliable (so best-effort and reliable subscribers both match) and 1000
deep. A reliable writer repairs a sample a reader missed only from its own history: at depth 1
each new /clock replaced the last before a loaded recorder had acknowledged it, and the
recorder lost 26 of 153 in one trial (issue 26). Keep-last never blocks the plant."""

EVENTS_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Trial events and summaries: reliable, and the last 1000 kept for late joiners (a monitor
or recorder that matched after trial 1 still gets it)."""

DIAGNOSTICS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""/diagnostics: a supervisor that matched late still sees the controller's last
acknowledgements."""


class CountingPublisher(Publisher):
    """A publisher that counts what it published (``published``): :func:`run_nodes` prints
    every node's counts per topic when it stops (:data:`PUBLISHED_PREFIX`), so a test can hold
    them against what the bag recorded."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.published = 0

    def publish(self, msg: Any) -> None:
        """Publish, then count."""
        super().publish(msg)
        self.published += 1


PUBLISHED_PREFIX = "[exo_ilc_ros] published "
"""Start of the line (stderr) a stopping process writes per node: ``<prefix><node> <JSON
{topic: count}>``."""


def published_counts(node: Node) -> dict[str, int]:
    """Per topic, what ``node``'s :class:`CountingPublisher` s published."""
    counts: dict[str, int] = {}
    for publisher in node.publishers:
        if isinstance(publisher, CountingPublisher):
            counts[publisher.topic_name] = counts.get(publisher.topic_name, 0) + \
                publisher.published
    return counts


def wall_clock() -> Clock:
    """A steady clock for timers that must run while simulated time stands still."""
    return Clock(clock_type=ClockType.STEADY_TIME)




def rcl_message(exc: Exception) -> str:
    """An RCLError's text without rcl's prefix and C source locations."""
    text = str(exc).removeprefix("failed to initialize rcl: ")
    text = re.sub(r",? at /[^,]*?:\d+", "", text).strip()
    if "parameter override rule" in text:
        text += " (a rule is -p name:=value, e.g. -p max_trials:=3)"
    return text


INBOX_PERIOD = 0.01
"""Seconds between two drains of an :class:`Inbox` (at most; also drained after every event
the executor handles)."""

INBOX_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
"""An inbox's sample subscriptions: 10 000 deep (100 s at 100 Hz, 3 s of a lock-step graph
at full speed) between two drains."""


class Inbox:
    """Raw subscriptions read in batches instead of one executor wake-up per message.

    A node that only needs a topic's messages every few milliseconds (the supervisor's trial
    samples, the recorder's every topic) would otherwise wake its Python thread once per
    message, on the same two cores as the plant and controller whose round trip it slows.
    The subscriptions live on a companion node ``<node>_inbox`` that no executor spins;
    :meth:`take` drains them (``rcl_take`` until empty). The owner calls it from its spin loop
    (``poll``, at least every :data:`INBOX_PERIOD`) and before acting on an event that must
    see every earlier message. Messages come back in the order DDS received them.

    Inboxes of one process (nodes composed in one container) share one subscription per
    topic, type and QoS: the sample is taken from DDS once, and every inbox of the topic gets
    it once from whichever drains first.
    """

    def __init__(self, owner: Node, name: str = "inbox") -> None:
        self.node = Node(f"{owner.get_name()}_{name}", namespace=owner.get_namespace(),
                         parameter_overrides=[Parameter("use_sim_time", value=False)],
                         start_parameter_services=False, enable_rosout=False)
        self._readers: list[_SharedReader] = []
        self._pending: list[tuple[int, str, bytes]] = []
        self._admit: dict[int, Callable[[bytes, bytes], bool]] = {}

    def subscribe(self, msg_type: Any, topic: str, qos: QoSProfile = INBOX_QOS,
                  admit: Callable[[bytes, bytes], bool] | None = None) -> Any:
        """A raw subscription drained by :meth:`take` (returned for its publisher count);
        with ``admit``, only messages for which ``admit(raw, sender's GID)`` is True."""
        name = topic if topic.startswith("/") else \
            f"{self.node.get_namespace().rstrip('/')}/{topic}"
        key = (name, msg_type, qos.history, qos.depth, qos.reliability, qos.durability)
        readers = _SHARED_READERS.setdefault(self.node.context, {})
        reader = readers.get(key)
        if reader is None:
            sub = self.node.create_subscription(msg_type, topic, _never_called, qos, raw=True)
            reader = readers[key] = _SharedReader(sub, self.node, key)
        if self not in reader.inboxes:  # the same topic twice in one inbox: read once
            reader.inboxes.append(self)
            self._readers.append(reader)
        if admit is not None:
            self._admit[id(reader)] = admit
        return reader.subscription

    def take(self) -> list[tuple[int, str, bytes]]:
        """Every waiting message as (DDS receive time in ns, topic, CDR bytes), in receive
        order."""
        for reader in self._readers:
            reader.drain()
        out, self._pending = self._pending, []
        if len(self._readers) > 1:
            out.sort(key=receive_time)
        return out

    def destroy(self) -> None:
        """Leave the shared subscriptions (the last inbox of one destroys it), then destroy
        the companion node once no other inbox reads through a subscription on it."""
        for reader in self._readers:
            reader.leave(self)
        self._readers.clear()
        self._pending.clear()
        _RETIRED.append(self)
        live = {id(r.node) for readers in _SHARED_READERS.values() for r in readers.values()}
        for inbox in [i for i in _RETIRED if id(i.node) not in live]:
            _RETIRED.remove(inbox)
            inbox.node.destroy_node()


class _SharedReader:
    """One raw subscription of a process and the inboxes that read it."""

    def __init__(self, subscription: Any, node: Node, key: tuple[Any, ...]) -> None:
        self.subscription = subscription
        self.node = node
        self.key = key
        self.topic: str = subscription.topic_name
        self.inboxes: list[Inbox] = []
        self.taker = RawTaker(subscription.handle)

    def drain(self) -> None:
        """Take every waiting message and hand it to each inbox of the topic (to those with
        an ``admit`` rule only the messages it admits)."""
        taken = self.taker.take_all()
        if taken:
            topic = self.topic
            for inbox in self.inboxes:
                admit = inbox._admit.get(id(self))
                inbox._pending.extend((t, topic, raw) for t, raw, gid in taken
                                      if admit is None or admit(raw, gid))

    def leave(self, inbox: Inbox) -> None:
        """``inbox`` reads no more; the last one out destroys the subscription."""
        self.inboxes.remove(inbox)
        if not self.inboxes:
            _SHARED_READERS.get(self.node.context, {}).pop(self.key, None)
            self.node.destroy_subscription(self.subscription)


_SHARED_READERS: dict[Any, dict[tuple[Any, ...], _SharedReader]] = {}
"""Per rclpy context: the inbox subscriptions by (topic, type, QoS)."""
_RETIRED: list[Inbox] = []
"""Destroyed inboxes whose companion node still carries a subscription other inboxes read."""


def _never_called(raw: bytes) -> None:  # pragma: no cover - inbox subscriptions are not spun
    raise RuntimeError("an inbox subscription was spun by an executor")


def receive_time(item: tuple[int, str, bytes]) -> int:
    """An inbox message's DDS receive time (ns): its sort key."""
    return item[0]


DRAIN_IDLE = 0.3
DRAIN_MAX = 3.0
"""After a stop (SIGINT/SIGTERM, or a node's fatal error), a node with ``DRAINS_ON_STOP`` is
spun on until its ``drain()`` handled nothing for DRAIN_IDLE s (at most DRAIN_MAX s), so what
the graph published before it was told to stop is still taken (the recorder writes it)."""


@runtime_checkable
class PollingNode(Protocol):
    """A node :func:`run_nodes` polls (an :class:`Inbox` owner)."""

    @property
    def exit_code(self) -> int | None:
        """Not None: the node hit a fatal error (already logged and reported on /diagnostics)
        and the process must stop with this code."""
        ...

    def poll(self) -> int | None:
        """Handle what waits in the inbox; returns how many messages (None: not counted).
        Called after every executor event and at least every :data:`INBOX_PERIOD`."""
        ...


@runtime_checkable
class DrainingNode(PollingNode, Protocol):
    """A :class:`PollingNode` that is drained after a stop until its inbox is quiet
    (:data:`DRAIN_IDLE`) and destroyed last (the bag recorder: what the graph published before
    the stop still reaches the bag)."""

    DRAINS_ON_STOP: ClassVar[bool]

    def drain(self) -> int:
        """Handle everything waiting, what ``poll`` defers included; returns how many
        messages."""
        ...


def spin(make_node: Callable[[], Node], args: list[str] | None = None) -> int:
    """Init, build the node, spin it until SIGINT/SIGTERM; its exit code (see
    :func:`run_nodes`)."""
    return run_nodes([make_node], args)


def run_nodes(factories: Sequence[Callable[[], Node]], args: list[str] | None = None) -> int:
    """Init, build the nodes in order and spin them in this one process with one
    EventsExecutor (``spin_once`` in a loop, never ``spin()``) until SIGINT/SIGTERM.

    Nodes of one process share one DDS participant, so a topic several of them read crosses
    the process boundary once (ROS 2 composition). A :class:`PollingNode` has its ``poll()``
    called after every event and at least every :data:`INBOX_PERIOD`. On stop, every node but
    the :class:`DrainingNode` ones is destroyed first, those are drained (:data:`DRAIN_IDLE`)
    and then destroyed (the recorder closes its bag). Each node's published counts
    (:data:`PUBLISHED_PREFIX`) are printed once the others can publish no more: out of the
    executor, the callbacks still queued for them run. Returns the exit code: 0, 2 for a
    configuration or bag error, or the first ``exit_code`` a polling node sets.
    """
    with realtime.node_process():  # the nodes' SCHED_FIFO requests apply while they run
        return _run_nodes(factories, args)


def _run_nodes(factories: Sequence[Callable[[], Node]], args: list[str] | None) -> int:
    stop: list[int] = []

    def on_signal(signum: int, frame: Any) -> None:
        stop.append(signum)

    parameters.given_command_line(list(sys.argv if args is None else args))
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:  # a bad --ros-args value: rcl says which and why
        print(f"error: invalid ROS arguments: {rcl_message(exc)}", file=sys.stderr, flush=True)
        parameters.given_command_line(None)
        return 2
    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    nodes: list[Node] = []
    code = 0
    try:
        executor = EventsExecutor()
        for make_node in factories:
            nodes.append(make_node())
            executor.add_node(nodes[-1])
        polling = [node for node in nodes if isinstance(node, PollingNode)]
        timeout = INBOX_PERIOD if polling else 0.1
        while not stop and rclpy.ok():
            executor.spin_once(timeout_sec=timeout)
            for node in polling:
                node.poll()
            codes = [node.exit_code for node in polling if node.exit_code is not None]
            if codes:  # a node that must stop (fatal error)
                code = int(codes[0])
                break
        draining = [node for node in polling
                    if isinstance(node, DrainingNode) and node.DRAINS_ON_STOP]
        leaving = [n for n in nodes if n not in draining]
        for node in leaving:
            executor.remove_node(node)
        # The executor lets go of their entities before they are destroyed, and runs the
        # callbacks already queued for them (a message that arrived while stopping): those
        # may publish, so only now is what they published final.
        _settle(executor)
        _deliver(nodes)
        for node in nodes:  # (a draining node's own status goes on while it drains)
            print(f"{PUBLISHED_PREFIX}{node.get_name()} "
                  f"{json.dumps(published_counts(node), sort_keys=True)}",
                  file=sys.stderr, flush=True)
        for node in leaving:
            nodes.remove(node)
            destroy(node)
        _drain(executor, [node.drain for node in draining])
    except ExoIlcError as exc:
        print(f"error: {exc}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for node in reversed(nodes):
            destroy(node)
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        parameters.given_command_line(None)
    return code


HEARD_TOPICS = (topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY)
"""The run's verdict: a node stopping waits (within
:func:`_deliver`'s budget) until some subscriber is matched on them, so a run that fails at
once is still heard (its ``finished``, transient local, reaches a reader matched late)."""


def _deliver(nodes: Sequence[Node], timeout: float = 3.0) -> None:
    """Wait (at most ``timeout`` s in all) until every reliable publisher's last messages were
    acknowledged by the subscribers matched now, and the :data:`HEARD_TOPICS` have a subscriber:
    a node that stops right after publishing (the supervisor's ``finished``, a last summary)
    would otherwise take them with it."""
    from rclpy.duration import Duration

    deadline = time.monotonic() + timeout
    for node in nodes:
        for publisher in list(node.publishers):
            while publisher.topic_name in HEARD_TOPICS and \
                    publisher.get_subscription_count() < 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            left = deadline - time.monotonic()
            if left <= 0:
                return
            try:
                publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))
            except Exception:  # best effort: a publisher rcl cannot wait on is not waited for
                continue


def _settle(executor: EventsExecutor, timeout: float = 1.0) -> None:
    """Spin until the EventsExecutor has handled everything posted so far (a node's removal
    included: it unregisters the node's entities then, and an rcl subscription destroyed
    before that crashed the process): a task posted now runs after them."""
    marker = executor.create_task(lambda: None)
    deadline = time.monotonic() + timeout
    while not marker.done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)


def destroy(node: Node) -> None:
    """Destroy ``node`` and the :class:`identified.IdentifiedSubscription` s on it (rclpy's
    ``destroy_node`` leaves waitables alone)."""

    for waitable in list(node.waitables):
        if isinstance(waitable, IdentifiedSubscription):
            waitable.destroy()
    node.destroy_node()


def _drain(executor: EventsExecutor, polls: Sequence[Callable[[], int | None]]) -> None:
    """Spin and call ``polls`` (the nodes' ``drain``) until none took a message for DRAIN_IDLE
    s (at most DRAIN_MAX)."""
    if not polls:
        return
    now = time.monotonic()
    deadline, last_message = now + DRAIN_MAX, now
    while rclpy.ok() and time.monotonic() < deadline and \
            time.monotonic() - last_message < DRAIN_IDLE:
        executor.spin_once(timeout_sec=INBOX_PERIOD)
        if sum(int(poll() or 0) for poll in polls):
            last_message = time.monotonic()
