"""``exo-ilc urdf``: write the arm's URDF from the config (the shipped urdf/ is made by this)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from ..core.params.config import Config, load_config, urdf_source
from .arguments import add_config_argument, json_file, write_output


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser("urdf", help="write the arm's URDF from the config (a URDF arm: "
                            "the chain the package uses of it)")
    add_config_argument(parser, "ROS parameter YAML over the shipped config")
    parser.add_argument("--out", type=json_file, help="output file (default: standard output)")
    parser.set_defaults(func=write_urdf)


def write_urdf(args: argparse.Namespace) -> int:
    """Generate and write: a cone arm's URDF, or a URDF arm's chain as the package uses it
    (:func:`used_chain_urdf`)."""
    from ..core.arm.build import build_arm
    from ..core.arm.urdf import arm_urdf
    config = load_config(args.config)
    if config["model.source"] == "urdf":
        text = used_chain_urdf(config)
    else:
        text = arm_urdf(build_arm(config), config["joint_names"], config["control.effort_limit"])
    write_output(text, args.out)
    return 0


def used_chain_urdf(config: Config) -> str:
    """The URDF of a URDF arm's chain as the package uses it: links above the base link and
    dropped branches left out, locked joints made fixed at their values, the links' shapes
    kept (:func:`~exo_ilc_ros.core.arm.mujoco_urdf.chain_urdf`); a comment says what was
    done and gravity in the base link's frame (the file's root: ``model.gravity_direction``
    reads it back)."""
    from ..core.arm.build import urdf_chain
    from ..core.arm.mujoco_urdf import chain_urdf
    chain = urdf_chain(config)
    text, _, _ = urdf_source(config.values)
    g = chain.gravity
    down = g / float(np.linalg.norm(g))
    locked = ", ".join(f"{name}: {value:g}" for name, value in chain.locked) or "none"
    dropped = ", ".join(chain.dropped_links) or "none"
    comment = (f"The chain {chain.base_link} -> {chain.tip_link} of {chain.source} as "
               f"exo_ilc_ros uses it (exo-ilc urdf): moving joints "
               f"{', '.join(chain.joint_names)}; locked joints made fixed ({locked}); links "
               f"dropped ({dropped}); links above the base left out. Gravity in "
               f"{chain.base_link}'s frame (this file's root): "
               f"[{', '.join(f'{x:.6g}' for x in g)}] m/s^2, model.gravity_direction "
               f"[{', '.join(f'{x:.6g}' for x in down)}]")
    comment = comment.replace("--", "- -")  # an XML comment may not hold a double hyphen
    return (f'<?xml version="1.0"?>\n<!-- {comment} -->\n'
            f"{chain_urdf(text, chain, shapes=True)}\n")
