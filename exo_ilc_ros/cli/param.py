"""``exo-ilc param get|set|list NODE [NAME] [VALUE]``: what ``ros2 param`` does, over the
standard parameter services (rcl_interfaces GetParameters / SetParameters / ListParameters)."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

import yaml

from ..core.errors import ExoIlcError


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
    parser.add_argument("--domain-id", type=int,
                        default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0),
                        help="ROS domain id of the graph (default: $ROS_DOMAIN_ID or 0)")
    parser.add_argument("--timeout", type=float, default=10.0,
                        help="seconds to wait for the node (default 10)")
    parser.set_defaults(func=param)


def parse_value(text: str) -> Any:
    """A command-line VALUE as a ROS parameter value (YAML, like ``ros2 param set``); a list of
    numbers with any float in it becomes all floats."""
    value = yaml.safe_load(text)
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
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    node = rclpy.create_node("exo_ilc_param", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        client = AsyncParameterClient(node, args.node.lstrip("/"))
        if not client.wait_for_services(timeout_sec=args.timeout):
            raise ParamError(f"node {args.node} not found on ROS domain {args.domain_id} within "
                             f"{args.timeout:g} s")

        def wait(future: Any) -> Any:
            executor.spin_until_future_complete(future, timeout_sec=args.timeout)
            if not future.done() or future.result() is None:
                raise ParamError(f"node {args.node} did not answer within {args.timeout:g} s")
            return future.result()

        if args.action == "list":
            for name in sorted(wait(client.list_parameters()).result.names):
                print(name)
            return 0
        if args.action == "get":
            values = wait(client.get_parameters([args.name])).values
            if not values or values[0].type == 0:
                raise ParamError(f"{args.node} has no parameter {args.name}")
            print(_value_of(values[0]))
            return 0
        result = wait(client.set_parameters([Parameter(args.name,
                                                       value=parse_value(args.value))]))
        outcome = result.results[0]
        if outcome.successful:
            print("Set parameter successful")
            return 0
        print(f"Setting parameter failed: {outcome.reason}", file=sys.stderr)
        return 1
    finally:
        executor.remove_node(node)
        node.destroy_node()
        context.try_shutdown()


def _value_of(message: Any) -> Any:
    """The Python value of an rcl_interfaces/ParameterValue."""
    from rclpy.parameter import parameter_value_to_python

    value = parameter_value_to_python(message)
    return list(value) if not isinstance(value, (str, bytes)) and hasattr(value, "__len__") \
        else value
