"""``exo-ilc param get|set|list NODE [NAME] [VALUE]``: what ``ros2 param`` does, over the
standard parameter services (rcl_interfaces GetParameters / SetParameters / ListParameters)."""

from __future__ import annotations

import argparse
import difflib
import os
import sys
import time
from typing import Any

import yaml

from ..core.errors import ExoIlcError
from ..core.params.config import load_ros_yaml, yaml_problem
from .arguments import domain_id, number


class ParamError(ExoIlcError):
    """The node's parameter services did not answer or refused."""


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "param", help="get, set or list a running node's parameters",
        description="Talk to a running node's parameter services (what `ros2 param` does). "
        "A set of an ilc_supervisor schedule parameter takes effect at the next trial.")
    parser.add_argument("action", choices=("get", "set", "list"))
    parser.add_argument("node", help="node name, e.g. ilc_supervisor")
    parser.add_argument("name", nargs="?", help="parameter name (get, set), e.g. "
                        "schedule.position.threshold_low")
    parser.add_argument("value", nargs="?", help="new value as YAML, e.g. '[1.0, 2.0, 1.0]'")
    parser.add_argument("--domain-id", type=domain_id,
                        help="ROS domain id of the graph (default: $ROS_DOMAIN_ID or 0)")
    parser.add_argument("--timeout", type=number(strictly_positive=True), default=10.0,
                        help="seconds to wait for the node (default 10)")
    parser.set_defaults(func=param)


def parse_value(text: str) -> Any:
    """A command-line VALUE as a ROS parameter value (YAML, like ``ros2 param set``); a list of
    numbers with any float in it becomes all floats."""
    try:
        value = load_ros_yaml(text)
    except yaml.YAMLError as exc:
        raise ParamError(f"VALUE {text!r} is not a valid YAML value ({yaml_problem(exc)}); "
                         "give e.g. 1.5, true, text or [1.0, 2.0, 1.0]") from None
    if isinstance(value, dict):
        raise ParamError(f"VALUE {text!r} is a mapping; a ROS parameter is a number, bool, "
                         "string or a list of one of these")
    if isinstance(value, list) and any(isinstance(v, (list, dict)) for v in value):
        raise ParamError(f"VALUE {text!r} nests lists or mappings; a ROS parameter list is flat")
    if isinstance(value, list) and len({_list_kind(v) for v in value}) > 1:
        raise ParamError(f"VALUE {text!r} mixes types; a ROS parameter list holds numbers, "
                         "bools or strings, one kind")
    if isinstance(value, int) and not isinstance(value, bool) and not -2**63 <= value < 2**63:
        raise ParamError(f"VALUE {text!r} does not fit a 64-bit integer")
    if value is None:
        raise ParamError(f"VALUE {text!r} is empty (null); ROS parameters cannot be unset here")
    if isinstance(value, list) and value and \
            all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value) and \
            any(isinstance(v, float) for v in value):
        value = [float(v) for v in value]
    return value


def param(args: argparse.Namespace) -> int:
    """Run one parameter action against ``args.node``."""
    if args.action in ("get", "set") and not args.name:
        raise ParamError(f"param {args.action} needs a parameter NAME")
    if args.action == "set" and args.value is None:
        raise ParamError("param set needs a VALUE")
    if args.action == "list" and args.name is not None:
        raise ParamError(f"param list takes no NAME, got {args.name!r}")
    if args.action == "get" and args.value is not None:
        raise ParamError(f"param get takes no VALUE, got {args.value!r}")
    value = parse_value(args.value) if args.action == "set" else None
    domain = args.domain_id if args.domain_id is not None else _environment_domain_id()
    node_name = _node_name(args.node)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("exo_ilc_param", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        client = AsyncParameterClient(node, node_name)
        _wait_for_node(node, client, node_name, args.node, domain, args.timeout)

        def wait(future: Any) -> Any:
            executor.spin_until_future_complete(future, timeout_sec=args.timeout)
            if not future.done() or future.result() is None:
                raise ParamError(f"node {args.node} did not answer within {args.timeout:g} s")
            return future.result()

        names = sorted(wait(client.list_parameters()).result.names)
        if args.action == "list":
            for name in names:
                print(name)
            return 0
        if args.name not in names:
            raise ParamError(unknown_parameter(args.node, args.name, names))
        if args.action == "get":
            values = wait(client.get_parameters([args.name])).values
            if not values or values[0].type == 0:
                raise ParamError(unknown_parameter(args.node, args.name, names))
            print(_value_of(values[0]))
            return 0
        result = wait(client.set_parameters([Parameter(args.name, value=value)]))
        outcome = result.results[0]
        if outcome.successful:
            print("Set parameter successful")
            return 0
        print(f"Setting parameter failed: {args.name} = {args.value}: {outcome.reason}",
              file=sys.stderr)
        return 2  # the node refused the value: a refused input (docs/exit-codes.md), not a bug
    finally:
        executor.remove_node(node)
        node.destroy_node()
        context.try_shutdown()


def unknown_parameter(node: str, name: str, names: list[str]) -> str:
    """What to tell a user who named a parameter ``node`` does not have."""
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.6)
    if close:
        return (f"{node} has no parameter {name!r}; did you mean {' or '.join(close)}? "
                f"(`exo-ilc param list {node}` lists all {len(names)})")
    return f"{node} has no parameter {name!r}; its parameters: {', '.join(names)}"


def _list_kind(value: Any) -> str:
    """The ROS array type an item of a list value asks for (ints and floats mix: doubles)."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, (int, float)):
        return "number"
    return type(value).__name__


SETTLE = 5.0
"""Seconds the discovered nodes must stay the same (no new one appearing) for NODE to count as
missing among them; then a mistyped NODE fails with the names of the running ones (not after
--timeout). A graph still starting (its processes coming up one after another on a loaded
machine) keeps adding nodes, and the wait goes on."""


def _wait_for_node(node: Any, client: Any, target: str, given: str, domain: int,
                   timeout: float) -> None:
    """Until ``client``'s services are ready; ParamError when the graph's nodes are discovered
    and ``target`` is not one of them (listing them, with the closest name), or when no node
    answers within ``timeout``."""
    start = time.monotonic()
    seen_at: float | None = None
    wanted = "/" + target.lstrip("/")
    running: list[str] = []
    seen: list[str] = []
    while time.monotonic() - start < timeout:
        if client.wait_for_services(timeout_sec=0.1):
            return
        running = sorted({f"{ns.rstrip('/')}/{name}" for name, ns
                          in node.get_node_names_and_namespaces()} - {"/exo_ilc_param"})
        if wanted in running or not running:
            continue
        if seen_at is None or running != seen:  # discovery still finding nodes: wait on
            seen_at, seen = time.monotonic(), running
        if time.monotonic() - seen_at > SETTLE:
            close = difflib.get_close_matches(wanted, running, n=1)
            hint = f"; did you mean {close[0].lstrip('/')}?" if close else ""
            raise ParamError(f"no node {given} on ROS domain {domain}{hint} Running nodes: "
                             + ", ".join(n.lstrip("/") for n in running))
    raise ParamError(f"node {given} not found on ROS domain {domain} within {timeout:g} s"
                     + (f" (running: {', '.join(n.lstrip('/') for n in running)})" if running
                        else " (no node at all: is `exo-ilc run` running, and is ROS_DOMAIN_ID "
                        "the one it printed?)"))


def _environment_domain_id() -> int:
    """$ROS_DOMAIN_ID (0 when unset), checked like --domain-id."""
    text = os.environ.get("ROS_DOMAIN_ID", "") or "0"
    try:
        return domain_id(text)
    except argparse.ArgumentTypeError as exc:
        raise ParamError(f"environment variable ROS_DOMAIN_ID: {exc} (or give --domain-id)") \
            from None


def _node_name(text: str) -> str:
    """NODE as the node name (or /namespace/name) its parameter services are under."""
    from rclpy.validate_full_topic_name import validate_full_topic_name
    from rclpy.validate_node_name import validate_node_name

    name = text.lstrip("/")
    try:
        if "/" in name:
            validate_full_topic_name("/" + name)
            validate_node_name(name.rsplit("/", 1)[1])
        else:
            validate_node_name(name)
    except Exception as exc:  # rclpy's Invalid*Exception: says what is wrong and where
        raise ParamError(f"NODE {text!r} is not a valid node name: "
                         f"{str(exc).splitlines()[0]}") from None
    return name


def _value_of(message: Any) -> Any:
    """The Python value of an rcl_interfaces/ParameterValue."""
    from rclpy.parameter import parameter_value_to_python

    value = parameter_value_to_python(message)
    return list(value) if not isinstance(value, (str, bytes)) and hasattr(value, "__len__") \
        else value
