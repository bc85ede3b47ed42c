"""Every shipped config is a valid ROS parameter file for rcl itself (not only for PyYAML)."""

from __future__ import annotations

from pathlib import Path

import pytest
from rclpy.context import Context

CONFIGS = sorted((Path(__file__).resolve().parents[1] / "config").glob("*.yaml"))


@pytest.mark.parametrize("path", CONFIGS, ids=[p.name for p in CONFIGS])
def test_rcl_parses_shipped_config(path: Path) -> None:
    """rcl's YAML reader types a bare ``y`` or ``n`` as a bool; --params-file must still load."""
    context = Context()
    context.init(["exo_ilc_ros", "--ros-args", "--params-file", str(path)])
    context.shutdown()


def test_schema_parameters_validate_on_set_and_apply_after() -> None:
    """A live change is checked by validation.validate_update in the on-set callback and lands
    in ``pending`` only from the post-set callback: a change another callback refuses, or one
    that breaks a rule, leaves ``pending`` (and ``config``) as they were."""
    import rclpy
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from exo_ilc_ros.core.params import schema
    from exo_ilc_ros.nodes.parameters import SchemaParameters

    context = Context()
    rclpy.init(context=context)
    try:
        node = Node("ilc_supervisor", context=context)
        veto: list[str] = []
        node.add_on_set_parameters_callback(  # runs after SchemaParameters' (added later)
            lambda params: SetParametersResult(successful=not veto, reason="vetoed"))
        params = SchemaParameters(node, schema.SUPERVISOR)
        seen: list[float] = []
        params.listeners.append(lambda config: seen.append(config["error_bound"]))
        start = params.config

        def set_one(name: str, value: object) -> SetParametersResult:
            (result,) = node.set_parameters([Parameter(name, value=value)])
            return result

        veto.append("no")
        assert not set_one("error_bound", 0.006).successful
        assert params.pending is start and not seen  # validated, but never applied
        veto.clear()
        result = set_one("error_bound", -1.0)
        assert not result.successful and result.reason.startswith("error_bound: ")
        result = set_one("control.period", 0.02)
        assert result.reason == ("control.period: cannot change while the graph runs (restart "
                                 "the node with the new value)")
        assert params.pending is start and not seen
        assert set_one("error_bound", 0.006).successful
        assert params.pending["error_bound"] == 0.006 and seen == [0.006]
        assert params.config is start and start["error_bound"] == 0.005
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
