"""Launch the exo_ilc_ros graph: plant_simulator, computed_torque_controller, ilc_supervisor,
and bag_recorder beside them (and foxglove_bridge, the live view, with ``live:=true``).

    ros2 launch exo_ilc_ros exo_ilc.launch.py
    ros2 launch exo_ilc_ros exo_ilc.launch.py params_file:=my.yaml mass_uncertainty:=0.10
    ros2 launch exo_ilc_ros exo_ilc.launch.py bag_path:=bags/today record:=false
    ros2 launch exo_ilc_ros exo_ilc.launch.py plant:=mujoco     # MuJoCo, protocol homing
    ros2 launch exo_ilc_ros exo_ilc.launch.py live:=true live_port:=8765   # Foxglove live view

Every node reads the shipped config/exo_ilc.yaml, then ``params_file`` (any subset of keys,
same layout) if given. The nodes are those of ``exo_ilc_ros/nodes/registry.py``. The recorder
(a process of its own here) writes ``bag_path`` (default ``bags/<run_name>`` under the working
directory) and copies the run's effective config (written to a temporary file) into the bag.
The live view (docs/live-view.md) binds ``live_host`` (default 127.0.0.1: this machine only).
Without launch_ros (a PyPI-only install), ``exo-ilc run`` does the same.
"""

from __future__ import annotations

import os
import tempfile

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.launch_context import LaunchContext
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from exo_ilc_ros.nodes import registry
from launch import LaunchDescription

PACKAGE = "exo_ilc_ros"


def _nodes(context: LaunchContext) -> list[Node]:
    shipped = os.path.join(get_package_share_directory(PACKAGE), "config", "exo_ilc.yaml")
    params: list[object] = [shipped]
    user = LaunchConfiguration("params_file").perform(context)
    if user:
        params.append(user)
    delta = LaunchConfiguration("mass_uncertainty").perform(context)
    plant = LaunchConfiguration("plant").perform(context)
    if plant not in ("simulator", "mujoco"):
        raise ValueError(f"plant:={plant}: use simulator or mujoco")
    if plant == "mujoco":  # no reset service: every node runs the homing protocol
        params.append({"protocol": "homing"})
    nodes = []
    for entry in registry.GRAPH:
        node_params = list(params)
        executable = entry.name
        if entry.name == registry.PLANT.name:  # the plant's role and parameter section
            executable = registry.PLANTS[plant].name
            if delta:
                node_params.append({"mass_uncertainty": float(delta)})
        nodes.append(Node(package=PACKAGE, executable=executable, name=entry.name,
                          parameters=node_params, output="screen", emulate_tty=True))
    record = LaunchConfiguration("record").perform(context).lower() in ("true", "1", "yes")
    live = LaunchConfiguration("live").perform(context).lower() in ("true", "1", "yes")
    # With both, the recorder feeds the view (no extra DDS reader of the loop's topics).
    relay = os.path.join(tempfile.mkdtemp(prefix="exo_ilc_live_"), "relay.sock") \
        if record and live else ""
    if record:
        nodes.append(_recorder(user, delta, LaunchConfiguration("bag_path").perform(context),
                               plant, relay))
    if live:
        nodes.append(_live_view(user, delta, plant,
                                LaunchConfiguration("live_host").perform(context),
                                LaunchConfiguration("live_port").perform(context), relay))
    return nodes


def _effective_config_file(user: str, delta: str, plant: str, header: str) -> str:
    from exo_ilc_ros.core.params.config import load_config

    overrides: dict[str, object] = {"mass_uncertainty": float(delta)} if delta else {}
    if plant == "mujoco":
        overrides["protocol"] = "homing"
    config = load_config(user or None, overrides or None)
    config_file = os.path.join(tempfile.mkdtemp(prefix="exo_ilc_launch_"), "effective.yaml")
    with open(config_file, "w") as out:
        out.write(config.to_ros_yaml(header))
    return config_file


def _live_view(user: str, delta: str, plant: str, host: str, port: str,
               relay: str = "") -> Node:
    """foxglove_bridge, a process of its own, with the run's config (for the arm's URDF),
    fed by the recorder over ``relay`` if given."""
    params: dict[str, object] = {
        "config_file": _effective_config_file(user, delta, plant, "shown by foxglove_bridge"),
        "host": host or "127.0.0.1", "port": int(port or 8765), "relay": relay}
    return Node(package=PACKAGE, executable=registry.BRIDGE.name, name=registry.BRIDGE.name,
                parameters=[params], output="screen", emulate_tty=True)


def _recorder(user: str, delta: str, bag_path: str, plant: str = "simulator",
              relay: str = "") -> Node:
    config_file = _effective_config_file(user, delta, plant,
                                         "effective config of ros2 launch exo_ilc_ros")
    params: dict[str, object] = {"config_file": config_file, "relay": relay}
    if bag_path:
        params["bag_path"] = bag_path
    return Node(package=PACKAGE, executable=registry.RECORDER.name, name=registry.RECORDER.name,
                parameters=[params], output="screen", emulate_tty=True)


def generate_launch_description() -> LaunchDescription:
    """The graph's nodes with the shipped parameters (and the user's file on top), recorded."""
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value="",
                              description="ROS parameter YAML laid over config/exo_ilc.yaml"),
        DeclareLaunchArgument("mass_uncertainty", default_value="",
                              description="plant mass uncertainty delta (default: the YAML's)"),
        DeclareLaunchArgument("plant", default_value="simulator",
                              description="simulator (plant_simulator, reset/start services) or "
                              "mujoco (mujoco_plant, no services: protocol homing)"),
        DeclareLaunchArgument("record", default_value="true",
                              description="start bag_recorder (true/false)"),
        DeclareLaunchArgument("bag_path", default_value="",
                              description="the bag's directory (default: bags/<run_name>)"),
        DeclareLaunchArgument("live", default_value="false",
                              description="start foxglove_bridge, the live view (true/false)"),
        DeclareLaunchArgument("live_port", default_value="8765",
                              description="the live view's WebSocket port"),
        DeclareLaunchArgument("live_host", default_value="127.0.0.1",
                              description="the address the live view binds (0.0.0.0 exposes "
                              "the run to the network, without a password)"),
        OpaqueFunction(function=_nodes),
    ])
