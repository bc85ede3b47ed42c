"""container: several of the package's nodes in one process (ROS 2 composition).

``ros2 run exo_ilc_ros container ilc_supervisor bag_recorder --ros-args --params-file F``
builds the named nodes in order and spins them with one executor (:func:`.common.run_nodes`).
They share one DDS participant, so a topic several of them read crosses the process boundary
once: the recorder beside the supervisor costs the control loop much less than a recorder
process of its own (``bench/bag_bench.py``). A crash or kill takes every node of the process
down together.

ROS arguments apply to every node of the process: give per-node parameters in a params file
(keyed by node name), not with ``-p``, and do not remap ``__node``.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

from rclpy.node import Node

from . import registry
from .common import run_nodes

NODES: dict[str, str] = {node.name: node.factory for node in registry.NODES}
"""The nodes a container can run (every node of :mod:`.registry`): name -> ``module:class``."""

USAGE = f"usage: container NODE [NODE ...] [--ros-args ...]; NODE in {', '.join(NODES)}"


def node_factory(name: str) -> Callable[[], Node]:
    """The class of node ``name`` (KeyError if the package has no such node)."""
    module, _, cls = NODES[name].partition(":")
    factory: Callable[[], Node] = getattr(importlib.import_module(module), cls)
    return factory


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros container NODE [NODE ...] --ros-args ...``."""
    argv = list(sys.argv if args is None else args)
    end = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    names = argv[1:end]
    unknown = [name for name in names if name not in NODES]
    if not names or unknown or len(set(names)) != len(names):
        problem = f"unknown node {unknown[0]!r}" if unknown else \
            "no node named" if not names else "a node named twice"
        print(f"container: {problem}\n{USAGE}", file=sys.stderr, flush=True)
        return 2
    return run_nodes([node_factory(name) for name in names], argv)


if __name__ == "__main__":
    raise SystemExit(main())
