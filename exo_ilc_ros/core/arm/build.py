"""The arm a config describes (its ``model.*`` keys): the nominal model the computed torque
uses (:func:`build_arm`) and the plant (:func:`build_plant`: the masses scaled, eq (15), and a
person's segments, ``person.*``). ``model.source`` says where it comes from: the paper's
truncated cones (``cones``) or a URDF's chain (``urdf``, :mod:`.urdf_chain`)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..params import schema
from ..params.config import Config, urdf_path, urdf_source
from .body_segments import Segment, SegmentPlacement, arm_segments, with_segments
from .model import ArmModel, with_mass_scale
from .urdf import arm_urdf
from .urdf_chain import UrdfChain, read_urdf_chain

_CHAINS: dict[tuple[Any, ...], UrdfChain] = {}


def build_arm(config: Config) -> ArmModel:
    """The nominal arm of the config (the model the computed torque uses): a URDF arm with the
    person's segments only with ``person.in_nominal``."""
    if config["model.source"] == "urdf":
        return _urdf_arm(config, 0.0, bool(config["person.in_nominal"]))
    return ArmModel.from_links(config["model.link_masses"], config["model.link_lengths"],
                               config["model.radius_proximal"], config["model.radius_distal"],
                               config["model.joint_axes"], gravity_in_root(config))


def gravity_in_root(config: Config) -> np.ndarray:
    """The gravity acceleration (m/s^2) in the URDF root link's frame (a cone arm's Oxyz):
    ``model.gravity`` along ``model.gravity_direction`` (normalised)."""
    direction = np.array(config["model.gravity_direction"], dtype=float)
    return float(config["model.gravity"]) * (direction / float(np.linalg.norm(direction)))


def build_plant(config: Config) -> ArmModel:
    """The plant of the config: the robot's masses and inertias scaled by (1 + delta), eq (15)
    (delta: ``mass_uncertainty``; another delta: :meth:`Config.with_mass_uncertainty`), plus
    the person's segments with ``person.enabled`` (not scaled: the person's are de Leva's
    estimate either way)."""
    delta = float(config["mass_uncertainty"])
    if config["model.source"] == "urdf":
        return _urdf_arm(config, delta, bool(config["person.enabled"]))
    return with_mass_scale(build_arm(config), delta)


def _urdf_arm(config: Config, mass_uncertainty: float, person: bool) -> ArmModel:
    chain = urdf_chain(config)
    if mass_uncertainty != 0.0:
        chain = with_mass_scale(chain, mass_uncertainty)
    if person and config["person.enabled"]:
        segments, placements = person_segments(config)
        for segment, placement in placements.items():
            pose = chain.link_poses.get(placement.link)
            if pose is None or pose[0] < 0:
                where = "not a link of" if pose is None else "fixed to the base of"
                raise ConfigError(f"person.{segment}.link", f"link {placement.link!r} is "
                                  f"{where} the chain {chain.base_link!r} -> "
                                  f"{chain.tip_link!r} of {chain.source} (a segment moves "
                                  "with a link the joints move)")
        chain = with_segments(chain, segments, placements)
    return arm_from_chain(chain)


def person_segments(config: Config) -> tuple[tuple[Segment, ...], dict[str, SegmentPlacement]]:
    """The person's segments (de Leva 1996, :func:`.body_segments.arm_segments`) and where
    each is strapped (the segments with a ``person.<segment>.link``)."""
    lengths = {s: config[f"person.{s}.length"] for s in schema.PERSON_SEGMENTS
               if config[f"person.{s}.length"] > 0.0}
    segments = arm_segments(config["person.body_mass"], config["person.height"],
                            config["person.sex"], lengths)
    placements = {
        s: SegmentPlacement(config[f"person.{s}.link"], _xyz(config[f"person.{s}.origin"]),
                            _xyz(config[f"person.{s}.direction"]),
                            _xyz(config[f"person.{s}.sagittal_axis"]))
        for s in schema.PERSON_SEGMENTS if config[f"person.{s}.link"]}
    return segments, placements


def _xyz(value: list[float]) -> tuple[float, float, float]:
    return float(value[0]), float(value[1]), float(value[2])


def urdf_chain(config: Config) -> UrdfChain:
    """The URDF chain of a ``model.source: urdf`` config (read once per file contents, links and
    locks)."""
    locked = schema.parse_locked_joints(config["model.locked_joints"])
    gravity = gravity_in_root(config)
    key = (config.urdf_digest, config["model.base_link"], config["model.tip_link"],
           tuple(sorted(locked.items())), tuple(gravity.tolist()))
    chain = _CHAINS.get(key)
    if chain is None:
        chain = read_urdf_chain(urdf_path(config["model.urdf"]), config["model.base_link"],
                                config["model.tip_link"], locked, gravity)
        _CHAINS[key] = chain
    return chain


def urdf_joint_dynamics(config: Config) -> tuple[np.ndarray, np.ndarray]:
    """The viscous damping b (N m s/rad) and Coulomb friction F (N m) per joint the plant adds
    to the rigid body: the URDF's ``<dynamics damping friction>`` with
    ``model.urdf_joint_dynamics: apply``, zeros otherwise (``ignore``, a cone arm). The nominal
    model never holds them."""
    zeros = np.zeros(config.joints)
    if config["model.source"] != "urdf" or config["model.urdf_joint_dynamics"] != "apply":
        return zeros, zeros.copy()
    chain = urdf_chain(config)
    return chain.damping.astype(float), chain.friction.astype(float)


def arm_from_chain(chain: UrdfChain) -> ArmModel:
    """An :class:`ArmModel` of a URDF chain: its kernels' arrays and limits; each link's length
    is the distance to the next joint (the last: 0), its radii 0 (a URDF gives no cones)."""
    lengths = np.zeros(chain.dof)
    lengths[:-1] = np.linalg.norm(chain.offsets[1:], axis=1)
    zeros = np.zeros(chain.dof)
    return ArmModel(chain.masses.copy(), lengths, zeros, zeros.copy(), chain.axes.copy(),
                    chain.offsets.copy(), chain.coms.copy(), chain.inertias.copy(),
                    chain.gravity.copy(), chain.position_lower.copy(),
                    chain.position_upper.copy(), chain.velocity_limit.copy(),
                    chain.effort_limit.copy())


def view_urdf(config: Config) -> tuple[str, dict[str, float], str]:
    """What a viewer draws of the config's arm: its URDF (the cone arm's from :func:`arm_urdf`,
    a URDF arm's own file), the positions of the joints that do not move (a URDF arm's locked
    joints) and the URDF's root link."""
    if config["model.source"] != "urdf":
        return (arm_urdf(build_arm(config), config["joint_names"],
                         config["control.effort_limit"]), {}, "base_link")
    text, _, _ = urdf_source(config.values)
    root = ET.fromstring(text)
    children = {c.get("link") for c in root.iter("child")}
    roots = [link.get("name", "") for link in root.findall("link")
             if link.get("name") not in children]
    if config["person.enabled"]:
        text = with_person_visuals(root, *person_segments(config))
    return text, schema.parse_locked_joints(config["model.locked_joints"]), roots[0]


PERSON_COLOUR = "0.87 0.68 0.55 0.85"
"""RGBA of the person's segments in a viewer (skin, slightly transparent)."""


def with_person_visuals(urdf: ET.Element, segments: Sequence[Segment],
                        placements: Mapping[str, SegmentPlacement]) -> str:
    """The URDF text with each placed segment of the person drawn on its link: a cylinder
    (``visual`` named ``person_<segment>``) from the proximal joint along the segment's
    direction, its length the segment's and its radius that of a solid cylinder with the
    segment's mass and longitudinal moment (r = sqrt(2 I / m)). Visual only: the plant's
    inertia is :func:`person_segments`' (:func:`.body_segments.with_segments`)."""
    links = {link.get("name"): link for link in urdf.findall("link")}
    for segment in segments:
        placement = placements.get(segment.name)
        if placement is None or placement.link not in links:
            continue
        along = np.asarray(placement.direction, dtype=float)
        along = along / np.linalg.norm(along)
        centre = np.asarray(placement.origin, dtype=float) + 0.5 * segment.length * along
        pitch = float(np.arctan2(np.hypot(along[0], along[1]), along[2]))
        yaw = float(np.arctan2(along[1], along[0]))  # Rz(yaw) Ry(pitch) takes z onto ``along``
        radius = float(np.sqrt(2.0 * segment.inertia_longitudinal / segment.mass))
        visual = ET.SubElement(links[placement.link], "visual", name=f"person_{segment.name}")
        ET.SubElement(visual, "origin", xyz=" ".join(f"{x:.6g}" for x in centre),
                      rpy=f"0 {pitch:.6g} {yaw:.6g}")
        geometry = ET.SubElement(visual, "geometry")
        ET.SubElement(geometry, "cylinder", radius=f"{radius:.6g}",
                      length=f"{segment.length:.6g}")
        material = ET.SubElement(visual, "material", name="person")
        ET.SubElement(material, "color", rgba=PERSON_COLOUR)
    return ET.tostring(urdf, encoding="unicode")
