"""A serial arm from its URDF: the arrays the compiled kernels of
:mod:`exo_ilc_ros.core.arm.dynamics` take, read with the standard library's XML parser.

The chain runs from ``base_link`` to ``tip_link``. Its moving joints are the revolute and
continuous joints on that path that are not locked; every other link is merged, rigidly, into
the moving body it hangs from:

* fixed joints, and joints named in ``locked`` (any type, held at the given value: an angle for
  a revolute or continuous joint, a length for a prismatic one), join their child link to the
  parent's body (mass, centre of mass and inertia combined by the parallel-axis theorem);
* a subtree hanging off the chain from the base's body (the links before the first moving
  joint) through a joint that could move is dropped, whole: it is fixed to the ground as far as
  the chain is concerned (its links are listed in :attr:`UrdfChain.dropped_links`);
* a joint that could move anywhere else (a branch off a moving link, or beyond the tip) is an
  error naming it and the config key that fixes it: lock it, or choose another tip.

An empty ``base_link`` is the URDF's root link, an empty ``tip_link`` the last link every
longest chain below the base passes through (the single leaf, or where only fixed, locked or
prismatic joints branch off), or an error saying why the URDF does not tell.

The kernels' convention (:mod:`exo_ilc_ros.core.arm.dynamics`) is that all link frames are parallel
to the base frame at q = 0. A URDF's joint frames are rotated by their ``origin rpy``; with R0_i
the orientation of joint i's frame at q = 0 (in the base frame), the kernel's arrays are
``axes[i] = R0_i a_i``, ``offsets[i] = R0_i-1 p_i`` (joint i's origin from joint i-1's),
``coms[i] = R0_i c_i`` and ``inertias[i] = R0_i I_i R0_i^T`` (I_i about the body's centre of
mass), which leaves the dynamics unchanged (tested against Pinocchio). Gravity is given in the
URDF's root link's frame ((0, 0, -g) by default: URDFs are drawn z up; any vector, e.g. (0, -g,
0) for a model drawn y up, ``model.gravity_direction``) and expressed in the base link's frame
(the base's fixed or locked joints up to the root at their q = 0 or locked values).

Errors (:class:`UrdfError`) name the file or the element: missing file, bad XML, a joint that is
prismatic, floating or planar on the path, a branch that could move, a base or tip link that is
not there or not connected, a mass matrix that is singular. ``package://`` is resolved the ROS
way (``ament_index_python``) where the package is installed.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ModelError
from ..params.urdf_xml import (
    Inertial,
    UrdfError,
    UrdfJoint,
    axis_rotation,
    chain_ends,
    chain_path,
    check_moving_bodies,
    checked_locks,
    joint_tree,
    moving_joints,
    parse_urdf,
    read_urdf_text,
)
from .dynamics import inertia_and_bias
from .model import Gravity, gravity_vector

SINGULAR_TOLERANCE = 1e-10
"""A Cholesky pivot of the mass matrix below this share of its largest diagonal entry counts as
singular."""


@dataclass(frozen=True, eq=False)
class UrdfChain:
    """The moving chain from ``base_link`` to ``tip_link``: the kernels' arrays
    (:attr:`kernel_args`, as :attr:`exo_ilc_ros.core.arm.model.ArmModel.kernel_args`) and what the
    URDF says of each moving joint."""

    robot_name: str
    base_link: str
    tip_link: str
    joint_names: tuple[str, ...]
    link_names: tuple[str, ...]
    """The child link of each moving joint (its body carries the links merged into it)."""
    masses: np.ndarray
    axes: np.ndarray
    offsets: np.ndarray
    coms: np.ndarray
    inertias: np.ndarray
    gravity: np.ndarray
    position_lower: np.ndarray
    """rad; -inf for a continuous joint."""
    position_upper: np.ndarray
    effort_limit: np.ndarray
    """N m; inf where the URDF gives none."""
    velocity_limit: np.ndarray
    """rad/s; inf where the URDF gives none."""
    damping: np.ndarray
    """``<dynamics damping>`` (N m s/rad), 0 where absent."""
    friction: np.ndarray
    """``<dynamics friction>`` (N m), 0 where absent."""
    continuous: tuple[bool, ...]
    digest: str
    """SHA-256 of the URDF's text (its contents, not its path)."""
    locked: tuple[tuple[str, float], ...] = ()
    merged_links: tuple[tuple[str, ...], ...] = ()
    """Per moving joint: every link of its body (its child link first)."""
    dropped_links: tuple[str, ...] = ()
    link_poses: Mapping[str, tuple[int, np.ndarray, np.ndarray]] = field(default_factory=dict)
    """Every kept link: (moving joint whose body holds it, -1 for the base's; its rotation and
    origin in that body's frame as the kernels orient it, parallel to the base at q = 0)."""
    source: str = field(default="", compare=False)
    """The file read, or ``<text>``."""

    @property
    def dof(self) -> int:
        """Number of moving joints."""
        return len(self.joint_names)

    @property
    def kernel_args(self) -> tuple[np.ndarray, ...]:
        """(masses, axes, offsets, coms, inertias, gravity) for the compiled kernels."""
        return (self.masses, self.axes, self.offsets, self.coms, self.inertias, self.gravity)


class LimitError(ModelError):
    """A reference leaves a joint's URDF limits; the message names the joint, time and value."""


def check_reference_limits(chain: UrdfChain, time: np.ndarray, position: np.ndarray,
                           velocity: np.ndarray, what: str = "the reference") -> None:
    """:class:`LimitError` at the earliest sample where ``position`` (rad) leaves a joint's
    ``<limit lower upper>`` or ``|velocity|`` (rad/s) exceeds its ``<limit velocity>``
    (``position``, ``velocity``: one row per sample of ``time``, one column per joint)."""
    q, qd = np.asarray(position, dtype=float), np.asarray(velocity, dtype=float)
    shape = (np.shape(time)[0], chain.dof)
    if q.shape != shape or qd.shape != shape:
        raise LimitError(f"{what}: {q.shape[1] if q.ndim == 2 else '?'} joints, the URDF's "
                         f"chain has {chain.dof} ({', '.join(chain.joint_names)})")
    checks = [(q < chain.position_lower, q, chain.position_lower, "q", "rad", "below its lower",
               "lower"),
              (q > chain.position_upper, q, chain.position_upper, "q", "rad", "above its upper",
               "upper"),
              (np.abs(qd) > chain.velocity_limit, qd, chain.velocity_limit, "qdot", "rad/s",
               "beyond its", "velocity")]
    first: tuple[int, int, int] | None = None
    for c, (outside, _, _, _, _, _, _) in enumerate(checks):
        for j in range(chain.dof):
            hits = np.flatnonzero(outside[:, j])
            if hits.size and (first is None or hits[0] < first[0]):
                first = (int(hits[0]), j, c)
    if first is None:
        return
    i, j, c = first
    _, values, limits, symbol, unit, relation, attribute = checks[c]
    raise LimitError(f"{what}: joint {chain.joint_names[j]!r} at t = {float(time[i]):.4g} s: "
                     f"{symbol} = {values[i, j]:.6g} {unit} is {relation} limit "
                     f"{limits[j]:.6g} {unit} ({chain.source} <limit {attribute}>)")


@dataclass
class _Body:
    """A rigid body being merged: masses, centres of mass and central inertias in its frame."""

    links: list[str]
    parts: list[tuple[float, np.ndarray, np.ndarray]]

    def add(self, inertial: Inertial | None, rotation: np.ndarray, origin: np.ndarray) -> None:
        if inertial is None or (inertial.mass == 0.0 and not np.any(inertial.inertia)):
            return
        r = rotation @ inertial.rotation
        self.parts.append((inertial.mass, rotation @ inertial.origin + origin,
                           r @ inertial.inertia @ r.T))

    def combined(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass, centre of mass and inertia about it (parallel-axis theorem)."""
        if not self.parts:
            return 0.0, np.zeros(3), np.zeros((3, 3))
        if len(self.parts) == 1:
            return self.parts[0]
        mass = float(sum(m for m, _, _ in self.parts))
        com = np.zeros(3)
        if mass > 0.0:
            for m, c, _ in self.parts:
                com += m * c
            com /= mass
        inertia = np.zeros((3, 3))
        for m, c, i in self.parts:
            d = c - com
            inertia += i + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
        return mass, com, inertia


def _fixed_transform(joint: UrdfJoint, value: float) -> tuple[np.ndarray, np.ndarray]:
    """Child frame in the parent's of a fixed joint, or of a locked one at ``value``."""
    if joint.type in ("revolute", "continuous"):
        return joint.rotation @ axis_rotation(joint.axis, value), joint.origin
    if joint.type == "prismatic":
        return joint.rotation, joint.origin + joint.rotation @ (value * joint.axis)
    return joint.rotation, joint.origin


def read_urdf_chain(source: str | Path, base_link: str, tip_link: str,
                    locked: Mapping[str, float] | None = None,
                    gravity: Gravity = 9.81) -> UrdfChain:
    """The chain from ``base_link`` to ``tip_link`` of the URDF at ``source`` (a path, a
    ``package://`` URI, or the URDF's text; an empty end found in the URDF,
    :func:`~exo_ilc_ros.core.params.urdf_xml.chain_ends`), ``locked`` joints held at the given
    values; ``gravity`` (m/s^2) along the root link's -z, or its vector in the root link's
    frame (module docstring)."""
    text, where = read_urdf_text(source)
    robot, links, joints = parse_urdf(text, where)
    locked = checked_locks(dict(locked or {}), joints, where)
    parent_joint, children = joint_tree(links, joints, where)
    base_link, tip_link = chain_ends(base_link, tip_link, links, parent_joint, children, locked,
                                     where)
    moving = moving_joints(chain_path(base_link, tip_link, links, parent_joint, where), locked,
                           base_link, tip_link, where)
    check_moving_bodies(moving, children, locked, base_link, tip_link, where)
    bodies, frame_of, dropped = _bodies(base_link, moving, links, children, locked)
    masses, axes, offsets, coms, inertias, orientations = _kernel_arrays(moving, bodies,
                                                                         frame_of)
    poses = {}
    for name, (body, rotation, origin) in frame_of.items():
        r0 = orientations[body - 1] if body > 0 else np.eye(3)
        poses[name] = (body - 1, r0 @ rotation, r0 @ origin)
    base_down = _base_orientation(base_link, parent_joint, locked)
    g = base_down.T @ gravity_vector(gravity)
    chain = UrdfChain(
        robot, base_link, tip_link, tuple(j.name for j in moving),
        tuple(j.child for j in moving), masses, axes, offsets, coms, inertias, g,
        np.array([-math.inf if j.type == "continuous" else j.lower for j in moving]),
        np.array([math.inf if j.type == "continuous" else j.upper for j in moving]),
        np.array([j.effort for j in moving]), np.array([j.velocity for j in moving]),
        np.array([j.damping for j in moving]), np.array([j.friction for j in moving]),
        tuple(j.type == "continuous" for j in moving),
        hashlib.sha256(text.encode("utf-8")).hexdigest(),
        tuple(sorted(locked.items())), tuple(tuple(b.links) for b in bodies[1:]),
        tuple(dropped), poses, where)
    _check_mass_matrix(chain, where)
    return chain


_Frame = tuple[int, np.ndarray, np.ndarray]
"""(body, rotation, origin) of a link's frame in its body's frame (body 0: the base's; i + 1:
moving joint i's)."""


def _bodies(base_link: str, moving: list[UrdfJoint], links: Mapping[str, Inertial | None],
            children: Mapping[str, list[UrdfJoint]], locked: Mapping[str, float]
            ) -> tuple[list[_Body], dict[str, _Frame], list[str]]:
    """Every link merged into the rigid body it belongs to, each link's frame in its body, and
    the links dropped (a branch off the base's body that could move)."""
    moving_names = {j.name for j in moving}
    bodies = [_Body([base_link], []) for _ in range(len(moving) + 1)]
    dropped: list[str] = []
    starts = [(0, base_link)] + [(i + 1, j.child) for i, j in enumerate(moving)]
    frame_of: dict[str, _Frame] = {}
    for body, start in starts:
        bodies[body].links = [start]
        stack = [(start, np.eye(3), np.zeros(3))]
        while stack:
            name, rotation, origin = stack.pop()
            frame_of[name] = (body, rotation, origin)
            bodies[body].add(links[name], rotation, origin)
            for joint in children[name]:
                if joint.name in moving_names:
                    continue  # starts the next body
                if joint.type == "fixed" or joint.name in locked:
                    r, p = _fixed_transform(joint, locked.get(joint.name, 0.0))
                    stack.append((joint.child, rotation @ r, rotation @ p + origin))
                    bodies[body].links.append(joint.child)
                else:  # off the base's body (check_moving_bodies refused any other)
                    dropped.extend(_subtree(joint.child, children))
    return bodies, frame_of, dropped


def _kernel_arrays(moving: list[UrdfJoint], bodies: list[_Body], frame_of: Mapping[str, _Frame]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                              list[np.ndarray]]:
    """masses, axes, offsets, coms, inertias in the kernels' convention (module docstring) and
    each moving body's orientation R0_i at q = 0."""
    n = len(moving)
    masses = np.zeros(n)
    axes = np.zeros((n, 3))
    offsets = np.zeros((n, 3))
    coms = np.zeros((n, 3))
    inertias = np.zeros((n, 3, 3))
    orientation = np.eye(3)  # R0 of the previous body (the base's: identity)
    orientations = []
    for i, joint in enumerate(moving):
        _, frame_rotation, frame_origin = frame_of[joint.parent]  # the previous body's frame
        rotation = frame_rotation @ joint.rotation
        origin = frame_rotation @ joint.origin + frame_origin
        offsets[i] = orientation @ origin
        orientation = orientation @ rotation
        orientations.append(orientation)
        axes[i] = orientation @ joint.axis
        mass, com, inertia = bodies[i + 1].combined()
        masses[i] = mass
        coms[i] = orientation @ com
        inertias[i] = orientation @ inertia @ orientation.T
    return masses, axes, offsets, coms, inertias, orientations


def _subtree(link: str, children: Mapping[str, list[UrdfJoint]]) -> list[str]:
    out, stack = [], [link]
    while stack:
        name = stack.pop()
        out.append(name)
        stack.extend(j.child for j in children[name])
    return out


def _base_orientation(base_link: str, parent_joint: Mapping[str, UrdfJoint],
                      locked: Mapping[str, float]) -> np.ndarray:
    """The base link's orientation in the URDF's root link (joints above it at q = 0 or their
    locked values)."""
    rotation = np.eye(3)
    link = base_link
    while link in parent_joint:
        joint = parent_joint[link]
        r, _ = _fixed_transform(joint, locked.get(joint.name, 0.0))
        rotation = r @ rotation
        link = joint.parent
    return rotation


def _check_mass_matrix(chain: UrdfChain, where: str, samples: int = 8) -> None:
    """:class:`UrdfError` naming the first joint whose column of a(q) is (numerically) a
    combination of the earlier ones, at q = 0 or at seeded random configurations within the
    position limits."""
    rng = np.random.default_rng(0)
    lower = np.where(np.isfinite(chain.position_lower), chain.position_lower, -math.pi)
    upper = np.where(np.isfinite(chain.position_upper), chain.position_upper, math.pi)
    zero = np.zeros(chain.dof)
    for k in range(samples):
        q = np.clip(zero, lower, upper) if k == 0 else rng.uniform(lower, upper)
        a, _ = inertia_and_bias(np.ascontiguousarray(q), zero, *chain.kernel_args)
        joint = _singular_column(a)
        if joint is not None:
            name = chain.joint_names[joint]
            raise UrdfError(
                f"{where}: the mass matrix of {chain.base_link!r} -> {chain.tip_link!r} is "
                f"singular at joint {name!r} (q = {np.round(q, 3).tolist()}): nothing beyond "
                f"it has inertia about its axis that the earlier joints do not already move "
                f"(give link {chain.link_names[joint]!r} or the links after it mass and "
                "inertia, or lock the joint)")


def _singular_column(a: np.ndarray) -> int | None:
    """Index of the first Cholesky pivot below :data:`SINGULAR_TOLERANCE` x max diag, or None."""
    n = a.shape[0]
    scale = max(float(np.max(np.abs(np.diag(a)))), 1e-300)
    low = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1):
            s = a[i, j] - float(low[i, :j] @ low[j, :j])
            if i == j:
                if s <= SINGULAR_TOLERANCE * scale:
                    return i
                low[i, i] = math.sqrt(s)
            else:
                low[i, j] = s / low[j, j]
    return None
