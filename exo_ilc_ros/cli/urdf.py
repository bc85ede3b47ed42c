"""``exo-ilc urdf``: write the arm's URDF from the config (the shipped urdf/ is made by this)."""

from __future__ import annotations

import argparse
from typing import Any

from ..core.params.config import load_config, urdf_source
from .arguments import add_config_argument, json_file, write_output


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser("urdf", help="write the arm's URDF from the config")
    add_config_argument(parser, "ROS parameter YAML over the shipped config")
    parser.add_argument("--out", type=json_file, help="output file (default: standard output)")
    parser.set_defaults(func=write_urdf)


def write_urdf(args: argparse.Namespace) -> int:
    """Generate and write (a URDF arm: its own URDF, as read)."""
    from ..core.arm.build import build_arm
    from ..core.arm.urdf import arm_urdf
    config = load_config(args.config)
    if config["model.source"] == "urdf":  # the arm's own URDF, unchanged
        text, _, _ = urdf_source(config.values)
    else:
        text = arm_urdf(build_arm(config), config["joint_names"], config["control.effort_limit"])
    write_output(text, args.out)
    return 0
