"""A person's arm in the exoskeleton: upper arm, forearm and hand as rigid segments from body mass
and height, by de Leva's adjustment of the Zatsiorsky-Seluyanov parameters.

Source: P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters",
J Biomech 29(9):1223-1230 (1996), Table 4 (the values below as transcribed independently by
several open projects, digit for digit; see the project's note on arm segments). Per segment and
sex: the mean segment length L_ref of the reference subjects (male 73.0 kg, 1.741 m; female
61.9 kg, 1.735 m), the mass as a share of body mass, the centre of mass as a share of L from the
segment's origin (here the proximal joint: shoulder, elbow and wrist joint centres; the hand
runs from the wrist joint centre to the third metacarpal head), and the radii of gyration about
the centre of mass as shares of L, about the sagittal, transverse and longitudinal axes.

Scaling: m = share x body mass, L = L_ref x height / reference stature (or the person's
measured joint-to-joint length), I = m (r L)^2 about the centre of mass. "Sagittal" and
"transverse" are the anatomical axes the radii are about (sagittal: the anteroposterior axis;
transverse: the mediolateral one, about which flexion turns); which of the two the table's
columns mean is read differently by different users (it changes the upper arm and forearm by
<= 6 %, the hand by 22 %), so :func:`segment_inertial` takes the sagittal axis explicitly.

The segments are inertias to add to named links of the exoskeleton's chain
(:func:`with_segments`), as the person's arm strapped to it moves with those links.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..params.schema import PERSON_SEGMENTS
from ..params.urdf_xml import UrdfError
from .urdf_chain import UrdfChain


class Sex(Enum):
    """The table's two sets of reference subjects."""

    MALE = "male"
    FEMALE = "female"


@dataclass(frozen=True)
class SegmentTable:
    """One row of de Leva (1996) Table 4."""

    length_mm: float
    """L_ref, mean length of the reference subjects (mm)."""
    mass_share: float
    """Segment mass / body mass."""
    com_share: float
    """Centre of mass from the proximal joint / L."""
    radius_sagittal: float
    """Radius of gyration about the sagittal axis / L."""
    radius_transverse: float
    radius_longitudinal: float


REFERENCE_STATURE_M = {Sex.MALE: 1.741, Sex.FEMALE: 1.735}
"""Stature of de Leva's reference subjects (m)."""

SEGMENTS = PERSON_SEGMENTS
"""Shoulder -> elbow, elbow -> wrist, wrist -> third metacarpal head."""

DE_LEVA_1996: Mapping[tuple[str, Sex], SegmentTable] = {
    ("upper_arm", Sex.MALE): SegmentTable(281.7, 0.0271, 0.5772, 0.285, 0.269, 0.158),
    ("upper_arm", Sex.FEMALE): SegmentTable(275.1, 0.0255, 0.5754, 0.278, 0.260, 0.148),
    ("forearm", Sex.MALE): SegmentTable(268.9, 0.0162, 0.4574, 0.276, 0.265, 0.121),
    ("forearm", Sex.FEMALE): SegmentTable(264.3, 0.0138, 0.4559, 0.261, 0.257, 0.094),
    ("hand", Sex.MALE): SegmentTable(86.2, 0.0061, 0.7900, 0.628, 0.513, 0.401),
    ("hand", Sex.FEMALE): SegmentTable(78.0, 0.0056, 0.7474, 0.531, 0.454, 0.335),
}
"""de Leva (1996) Table 4: upper arm (SJC-EJC), forearm (EJC-WJC), hand (WJC-MET3)."""


@dataclass(frozen=True)
class Segment:
    """One segment of a person: mass, length, centre of mass from its proximal joint and its
    principal moments of inertia about the centre of mass."""

    name: str
    mass: float
    """kg."""
    length: float
    """m, proximal to distal joint."""
    com_distance: float
    """m, from the proximal joint along the segment."""
    inertia_sagittal: float
    """kg m^2, about the sagittal (anteroposterior) axis through the centre of mass."""
    inertia_transverse: float
    """kg m^2, about the transverse (mediolateral) axis."""
    inertia_longitudinal: float
    """kg m^2, about the segment's long axis."""


def arm_segments(body_mass: float, height: float, sex: Sex | str = Sex.MALE,
                 lengths: Mapping[str, float] | None = None) -> tuple[Segment, ...]:
    """Upper arm, forearm and hand of a person of ``body_mass`` (kg) and ``height`` (m) by
    de Leva (1996) Table 4 (module docstring); ``lengths`` (m, by segment name) replaces the
    scaled reference length of any segment with the person's measured one."""
    sex = Sex(sex)
    if not body_mass > 0.0 or not height > 0.0:
        raise ValueError(f"body mass and height must be > 0, got {body_mass} kg, {height} m")
    measured = dict(lengths or {})
    unknown = sorted(set(measured) - set(SEGMENTS))
    if unknown:
        raise ValueError(f"unknown segment(s) {unknown}; the segments are {list(SEGMENTS)}")
    out = []
    for name in SEGMENTS:
        row = DE_LEVA_1996[(name, sex)]
        length = measured.get(name, row.length_mm / 1000.0 * height / REFERENCE_STATURE_M[sex])
        if not length > 0.0:
            raise ValueError(f"segment {name}: length must be > 0, got {length} m")
        mass = row.mass_share * body_mass
        out.append(Segment(name, mass, length, row.com_share * length,
                           mass * (row.radius_sagittal * length) ** 2,
                           mass * (row.radius_transverse * length) ** 2,
                           mass * (row.radius_longitudinal * length) ** 2))
    return tuple(out)


@dataclass(frozen=True)
class SegmentPlacement:
    """Where a segment lies in a link's frame: its proximal joint centre ``origin``, its
    ``direction`` (proximal to distal) and its ``sagittal_axis`` (anteroposterior, normal to the
    direction), all in the link's frame."""

    link: str
    origin: tuple[float, float, float]
    direction: tuple[float, float, float]
    sagittal_axis: tuple[float, float, float]


def segment_inertial(segment: Segment, placement: SegmentPlacement
                     ) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, centre of mass, inertia tensor about it) of ``segment`` in the link's frame."""
    along = np.asarray(placement.direction, dtype=float)
    sagittal = np.asarray(placement.sagittal_axis, dtype=float)
    if np.linalg.norm(along) == 0.0 or np.linalg.norm(sagittal) == 0.0:
        raise ValueError(f"segment {segment.name} on {placement.link}: zero direction or axis")
    along = along / np.linalg.norm(along)
    sagittal = sagittal / np.linalg.norm(sagittal)
    if abs(float(along @ sagittal)) > 1e-9:
        raise ValueError(f"segment {segment.name} on {placement.link}: the sagittal axis must "
                         "be normal to the segment's direction")
    transverse = np.cross(along, sagittal)
    axes = np.column_stack([sagittal, transverse, along])
    inertia = axes @ np.diag([segment.inertia_sagittal, segment.inertia_transverse,
                              segment.inertia_longitudinal]) @ axes.T
    com = np.asarray(placement.origin, dtype=float) + segment.com_distance * along
    return segment.mass, com, inertia


def with_segments(chain: UrdfChain, segments: Sequence[Segment],
                  placements: Mapping[str, SegmentPlacement]) -> UrdfChain:
    """``chain`` with each segment's inertia added to the moving body of its placement's link
    (``placements`` by segment name; a segment without a placement is left out). A link of the
    base's body gets nothing (it does not move); a link not in the chain is an error."""
    masses, coms = chain.masses.copy(), chain.coms.copy()
    inertias = chain.inertias.copy()
    for segment in segments:
        placement = placements.get(segment.name)
        if placement is None:
            continue
        pose = chain.link_poses.get(placement.link)
        if pose is None:
            raise UrdfError(f"{chain.source}: segment {segment.name}: link {placement.link!r} is "
                            f"not in the chain {chain.base_link!r} -> {chain.tip_link!r}")
        body, rotation, origin = pose
        if body < 0:
            continue
        mass, com, inertia = segment_inertial(segment, placement)
        com = rotation @ com + origin
        inertia = rotation @ inertia @ rotation.T
        total = masses[body] + mass
        combined = (masses[body] * coms[body] + mass * com) / total
        d0, d1 = coms[body] - combined, com - combined
        inertias[body] = (inertias[body] + inertia
                          + masses[body] * (float(d0 @ d0) * np.eye(3) - np.outer(d0, d0))
                          + mass * (float(d1 @ d1) * np.eye(3) - np.outer(d1, d1)))
        masses[body], coms[body] = total, combined
    return dataclasses.replace(chain, masses=masses, coms=coms, inertias=inertias)
