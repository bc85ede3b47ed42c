"""``exo-ilc ros2-control``: the ros2_control ``controllers.yaml`` for the config's arm (its
joints, in ``joint_names`` order, and the update rate of ``control.period``); the shipped
``config/ros2_control/controllers.yaml`` is this command's output for the shipped config."""

from __future__ import annotations

import argparse
from typing import Any

from ..core.params.config import Config, load_config
from .arguments import add_config_argument, json_file, write_output


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser("ros2-control", help="write the ros2_control controllers.yaml for "
                            "the config's arm (a URDF arm's joints: --config config/arms/...)")
    add_config_argument(parser, "ROS parameter YAML over the shipped config (e.g. an arm file)")
    parser.add_argument("--out", type=json_file, help="output file (default: standard output)")
    parser.set_defaults(func=write_controllers)


def controllers_yaml(config: Config) -> str:
    """The controller_manager configuration meeting the topic contract of
    exo_ilc_ros/wire/topics.py for ``config``'s joints."""
    rate = 1.0 / config["control.period"]
    rate_text = str(int(round(rate))) if abs(rate - round(rate)) < 1e-9 else repr(rate)
    joints = "[" + ", ".join(config["joint_names"]) + "]"
    period = f"{config['control.period']:g}"
    count = {1: "one", 2: "two", 3: "three"}.get(config.joints, str(config.joints))
    return f"""\
# exo_ilc_ros on your own arm: a ros2_control controller_manager configuration that meets the
# topic contract of exo_ilc_ros/wire/topics.py (docs/your-arm.md). Written by exo-ilc ros2-control.
#   ros2 run controller_manager ros2_control_node --ros-args --params-file controllers.yaml
#   ros2 run controller_manager spawner joint_state_broadcaster effort_controller
# Then start computed_torque_controller and ilc_supervisor (not plant_simulator) with
# protocol: homing, use_sim_time: false and watchdog_min_timeout: 0 (see docs/your-arm.md).

controller_manager:
  ros__parameters:
    update_rate: {rate_text:<22} # Hz: 1 / control.period ({period} s)
    joint_state_broadcaster:
      type: joint_state_broadcaster/JointStateBroadcaster
    effort_controller:                 # the name makes its topic /effort_controller/commands
      type: effort_controllers/JointGroupEffortController

joint_state_broadcaster:
  ros__parameters:
    # Only the {count} joints, position and velocity (effort if the hardware has it): the
    # controller's and the supervisor's /joint_states gate refuses unknown joint names.
    joints: {joints}
    interfaces: [position, velocity, effort]

effort_controller:
  ros__parameters:
    # The order of std_msgs/Float64MultiArray data in /effort_controller/commands: joint_names.
    joints: {joints}
"""


def write_controllers(args: argparse.Namespace) -> int:
    """Generate and write (the update rate of the period ``control.period_rule`` gives)."""
    from ..core.loop.rate import with_control_rate  # numba's arm model: not at CLI start

    text = controllers_yaml(with_control_rate(load_config(args.config)))
    write_output(text, args.out)
    return 0
