"""Launch the exo_ilc_ros graph: plant_simulator, computed_torque_controller, ilc_supervisor.

    ros2 launch exo_ilc_ros exo_ilc.launch.py
    ros2 launch exo_ilc_ros exo_ilc.launch.py params_file:=my.yaml mass_uncertainty:=0.10

Every node reads the shipped config/exo_ilc.yaml, then ``params_file`` (any subset of keys,
same layout) if given. Without launch_ros (a PyPI-only install), ``exo-ilc run`` does the same.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.launch_context import LaunchContext
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

NODES = ("plant_simulator", "computed_torque_controller", "ilc_supervisor")


def _nodes(context: LaunchContext) -> list[Node]:
    shipped = os.path.join(get_package_share_directory("exo_ilc_ros"), "config",
                           "exo_ilc.yaml")
    params: list[object] = [shipped]
    user = LaunchConfiguration("params_file").perform(context)
    if user:
        params.append(user)
    delta = LaunchConfiguration("mass_uncertainty").perform(context)
    nodes = []
    for name in NODES:
        node_params = list(params)
        if name == "plant_simulator" and delta:
            node_params.append({"mass_uncertainty": float(delta)})
        nodes.append(Node(package="exo_ilc_ros", executable=name, name=name,
                          parameters=node_params, output="screen", emulate_tty=True))
    return nodes


def generate_launch_description() -> LaunchDescription:
    """The three nodes with the shipped parameters (and the user's file on top)."""
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value="",
                              description="ROS parameter YAML laid over config/exo_ilc.yaml"),
        DeclareLaunchArgument("mass_uncertainty", default_value="",
                              description="plant mass uncertainty delta (default: the YAML's)"),
        OpaqueFunction(function=_nodes),
    ])
