"""Plumbing every node shares: schema parameters as ROS parameters, the set-parameters guard,
QoS profiles, diagnostics helpers and the spin loop."""

from __future__ import annotations

import array
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..core import schema
from ..core.config import Config, load_config
from ..core.errors import ConfigError

SAMPLES_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
"""/joint_states and the effort commands: reliable, deep enough that no sample of a trial is
lost even in real-time mode."""

LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""/ilc/feedforward: the last profile is delivered to late joiners."""

CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
"""/clock publisher (reliable, so best-effort and reliable subscribers both match)."""

EVENTS_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Trial events and summaries: reliable, and the last 1000 kept for late joiners (a monitor
or recorder that matched after trial 1 still gets it)."""

DIAGNOSTICS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""/diagnostics: a supervisor that matched late still sees the controller's last
acknowledgements."""


def wall_clock() -> Clock:
    """A steady clock for timers that must run while simulated time stands still."""
    return Clock(clock_type=ClockType.STEADY_TIME)


class SchemaParameters:
    """Declares the schema's parameters of one node and guards changes to them.

    Every parameter of ``schema.parameters_of(section)`` is declared with the shipped YAML's
    value as default, so ``--params-file`` and ``-p`` override it. Types are dynamic and every
    value goes through the schema's ``coerce`` (a user writing ``0`` for a double is fine).
    Changes at runtime: ``live`` parameters are validated with the schema (and the rules
    between parameters) and accepted into :attr:`pending`; any other change is rejected with the
    reason. The node decides when :attr:`pending` takes effect.
    """

    def __init__(self, node: Node, section: str) -> None:
        self._node = node
        self._params = {p.name: p for p in schema.parameters_of(section)}
        defaults = load_config()
        for p in self._params.values():
            descriptor = ParameterDescriptor(description=p.description, dynamic_typing=True)
            node.declare_parameter(p.name, defaults[p.name], descriptor)
        values = defaults.values
        values.update({name: node.get_parameter(name).value for name in self._params})
        self.config: Config = Config(values, f"parameters of node {node.get_name()}")
        """The configuration the node started with (validated)."""
        self.pending: Config = self.config
        """The configuration including accepted live changes."""
        self.listeners: list[Callable[[Config], None]] = []
        node.add_on_set_parameters_callback(self._on_set_parameters)

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        changes: dict[str, Any] = {}
        for parameter in parameters:
            spec = self._params.get(parameter.name)
            if spec is None:
                if parameter.name in schema.ROS_BUILTIN:
                    continue
                return SetParametersResult(successful=False,
                                           reason=f"{parameter.name}: unknown parameter")
            if not spec.live:
                return SetParametersResult(
                    successful=False, reason=f"{spec.name}: cannot change while the graph runs "
                    "(restart the node with the new value)")
            changes[spec.name] = parameter.value
        if not changes:
            return SetParametersResult(successful=True)
        try:
            updated = self.pending.replace(changes)
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=f"{exc.key}: {exc.rule}")
        self.pending = updated
        for listener in self.listeners:
            listener(updated)
        return SetParametersResult(successful=True)


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
    """

    def __init__(self, owner: Node) -> None:
        self.node = Node(f"{owner.get_name()}_inbox", namespace=owner.get_namespace(),
                         parameter_overrides=[Parameter("use_sim_time", value=False)],
                         start_parameter_services=False, enable_rosout=False)
        self._subscriptions: list[Any] = []
        self._topics: list[str] = []

    def subscribe(self, msg_type: Any, topic: str, qos: QoSProfile = INBOX_QOS) -> Any:
        """A raw subscription drained by :meth:`take` (returned for its publisher count)."""
        sub = self.node.create_subscription(msg_type, topic, _never_called, qos, raw=True)
        self._subscriptions.append(sub)
        self._topics.append(sub.topic_name)
        return sub

    def take(self) -> list[tuple[int, str, bytes]]:
        """Every waiting message as (DDS receive time in ns, topic, CDR bytes), in receive
        order."""
        out: list[tuple[int, str, bytes]] = []
        for sub, topic in zip(self._subscriptions, self._topics, strict=True):
            handle = sub.handle
            with handle:
                while True:
                    taken = handle.take_message(sub.msg_type, True)
                    if taken is None:
                        break
                    raw, info = taken
                    out.append((int(info["received_timestamp"]), topic, raw))
        if len(self._subscriptions) > 1:
            out.sort(key=_receive_time)
        return out

    def destroy(self) -> None:
        """Destroy the companion node."""
        self.node.destroy_node()


def _never_called(raw: bytes) -> None:  # pragma: no cover - inbox subscriptions are not spun
    raise RuntimeError("an inbox subscription was spun by an executor")


def _receive_time(item: tuple[int, str, bytes]) -> int:
    return item[0]


def spin(make_node: Callable[[], Node], args: list[str] | None = None) -> int:
    """Init, build the node, spin it with the EventsExecutor until shutdown or Ctrl-C.

    A node with a ``poll()`` method (an :class:`Inbox` owner) has it called after every event
    and at least every :data:`INBOX_PERIOD`. Returns the exit code: 0, 2 for a configuration
    error, or the node's ``exit_code`` once it sets one (a fatal error it already logged and
    reported on /diagnostics).
    """
    rclpy.init(args=args)
    node: Node | None = None
    code = 0
    try:
        node = make_node()
        executor = EventsExecutor()
        executor.add_node(node)
        poll: Callable[[], None] | None = getattr(node, "poll", None)
        timeout = 0.1 if poll is None else INBOX_PERIOD
        while rclpy.ok():
            executor.spin_once(timeout_sec=timeout)
            if poll is not None:
                poll()
            stop = getattr(node, "exit_code", None)  # a node that must stop (fatal error)
            if stop is not None:
                code = int(stop)
                break
    except ConfigError as exc:
        print(f"error: {exc}", flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
