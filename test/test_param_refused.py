"""``exo-ilc param set`` with a value the node refuses exits 2 (a refused input,
docs/exit-codes.md), not 1 (a bug), and prints the node's reason."""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator

import pytest

rclpy = pytest.importorskip("rclpy")

from rcl_interfaces.msg import SetParametersResult  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from exo_ilc_ros.cli.main import main  # noqa: E402

NODE = "exo_ilc_refusing_node"


@pytest.fixture
def refusing_node() -> Iterator[None]:
    """A node with parameter ``gain`` (1.0) that refuses every value below 0, spun in a
    thread on this session's domain."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0")))
    node = rclpy.create_node(NODE, context=context)
    node.declare_parameter("gain", 1.0)

    def check(params: list) -> SetParametersResult:
        bad = [p for p in params if p.name == "gain" and p.value < 0]
        return SetParametersResult(successful=not bad,
                                   reason="gain must be >= 0" if bad else "")

    node.add_on_set_parameters_callback(check)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set() and context.ok():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        executor.remove_node(node)
        node.destroy_node()
        context.try_shutdown()


def test_refused_value_exits_2(refusing_node: None, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["param", "set", NODE, "gain", "-1.0", "--timeout", "20"]) == 2
    err = capsys.readouterr().err
    assert "Setting parameter failed: gain = -1.0: gain must be >= 0" in err
    assert main(["param", "set", NODE, "gain", "2.0", "--timeout", "20"]) == 0  # accepted
    assert main(["param", "get", NODE, "gain", "--timeout", "20"]) == 0
    assert capsys.readouterr().out.splitlines()[-1].strip() == "2.0"
