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
