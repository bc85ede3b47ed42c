"""The arm a config describes (its ``model.*`` keys): the nominal model the computed torque
uses; the plant scales its masses (:meth:`.model.ArmModel.with_mass_scale`)."""

from __future__ import annotations

from ..params.config import Config
from .model import ArmModel


def build_arm(config: Config) -> ArmModel:
    """The nominal arm of the config (the model the computed torque uses)."""
    return ArmModel.from_links(config["model.link_masses"], config["model.link_lengths"],
                               config["model.radius_proximal"], config["model.radius_distal"],
                               config["model.joint_axes"], config["model.gravity"])
