"""``exo-ilc layout``: write the live view's layout made for the config's arm (Foxglove,
Lichtblick or PlotJuggler; docs/live-view.md). The shipped config/layouts/ are made by this."""

from __future__ import annotations

import argparse
from typing import Any

from .arguments import input_file, json_file, write_output

APPS = ("foxglove", "lichtblick")


def register(sub: Any) -> None:
    """Add the sub-command (imports the generator only when run)."""
    parser = sub.add_parser("layout", help="write the live view's layout for the config's arm "
                            "(Foxglove, Lichtblick or PlotJuggler)")
    parser.add_argument("--config", type=input_file,
                        help="ROS parameter YAML over the shipped config")
    parser.add_argument("--app", choices=APPS, default="foxglove",
                        help="the app whose panel-title key the layout uses (default foxglove)")
    parser.add_argument("--plotjuggler", action="store_true",
                        help="write PlotJuggler's XML layout instead")
    parser.add_argument("-o", "--out", type=json_file,
                        help="output file (default: standard output)")
    parser.set_defaults(func=write_layout)


def write_layout(args: argparse.Namespace) -> int:
    """Generate and write."""
    from ..core.params.config import load_config
    from ..orchestration.live_layout import arm_layout, foxglove_json, plotjuggler_xml


    arm = arm_layout(load_config(args.config))
    write_output(plotjuggler_xml(arm) if args.plotjuggler else foxglove_json(arm, args.app),
                 args.out)
    return 0
