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


def spin(make_node: Callable[[], Node], args: list[str] | None = None) -> int:
    """Init, build the node, spin it with the EventsExecutor until shutdown or Ctrl-C.

    Returns the exit code: 0, 2 for a configuration error, or the node's ``exit_code`` once it
    sets one (a fatal error it already logged and reported on /diagnostics).
    """
    rclpy.init(args=args)
    node: Node | None = None
    code = 0
    try:
        node = make_node()
        executor = EventsExecutor()
        executor.add_node(node)
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
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
