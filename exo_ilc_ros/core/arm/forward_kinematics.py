"""Forward kinematics of a URDF's joint tree, per joint: what robot_state_publisher puts on
/tf (one parent -> child transform per joint), from the URDF's joint origins and axes alone.

For joint j with origin (xyz, rpy) and unit axis a, the child frame in the parent's is
``T_j(q) = [R_rpy(rpy) R_a(q) | xyz]`` (URDF: the origin first, then the joint's motion about
its axis in the joint frame). Revolute and continuous joints turn about a, prismatic ones
slide along it, fixed ones do not move. Checked against Pinocchio's ``oMf`` (test_live.py).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class UrdfJoint:
    """One joint of a URDF: its frames, origin and axis."""

    name: str
    kind: str
    parent: str
    child: str
    xyz: np.ndarray
    rotation: np.ndarray
    """R_rpy of the origin (3 x 3)."""
    axis: np.ndarray


def _vector(text: str | None, default: Sequence[float]) -> np.ndarray:
    return np.array([float(x) for x in text.split()] if text else default, dtype=float)


def rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF's fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = np.cos(rpy[0]), np.sin(rpy[0])
    cp, sp = np.cos(rpy[1]), np.sin(rpy[1])
    cy, sy = np.cos(rpy[2]), np.sin(rpy[2])
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation by ``angle`` about the unit ``axis``."""
    x, y, z = axis
    c, s = np.cos(angle), np.sin(angle)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def quaternion(rotation: np.ndarray) -> np.ndarray:
    """(x, y, z, w) of a rotation matrix (Shepperd's method: stable for every angle)."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s]
    out = np.array(q)
    return out if out[3] >= 0.0 else -out


def _product(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, ...]:
    """Hamilton product a b of (x, y, z, w) quaternions (the rotation b, then a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


Transform = tuple[str, str, tuple[float, ...], tuple[float, ...]]
"""(parent frame, child frame, translation x y z, rotation quaternion x y z w)."""


class UrdfKinematics:
    """The joints of a URDF, for per-joint transforms at given joint positions (plain floats:
    the live view computes one set per sample, so no numpy in :meth:`transforms`)."""

    def __init__(self, urdf: str) -> None:
        root = ET.fromstring(urdf)
        self.joints: list[UrdfJoint] = []
        for joint in root.iter("joint"):
            origin = joint.find("origin")
            axis = joint.find("axis")
            parent, child = joint.find("parent"), joint.find("child")
            if parent is None or child is None:
                raise ValueError(f"joint {joint.get('name')}: no parent or child link")
            xyz = _vector(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
            rpy = _vector(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
            a = _vector(axis.get("xyz") if axis is not None else None, (1.0, 0.0, 0.0))
            norm = float(np.linalg.norm(a))
            self.joints.append(UrdfJoint(str(joint.get("name")), str(joint.get("type")),
                                         str(parent.get("link")), str(child.get("link")),
                                         xyz, rpy_matrix(rpy), a / norm if norm else a))
        self.moving = [j.name for j in self.joints if j.kind != "fixed"]
        """The names of the joints a position is needed for, in URDF order."""
        self._plain = [(j.name, j.kind, j.parent, j.child,
                        tuple(float(x) for x in j.xyz),
                        tuple(float(x) for x in quaternion(j.rotation)),
                        tuple(float(x) for x in j.axis),
                        tuple(tuple(float(x) for x in row) for row in j.rotation))
                       for j in self.joints]

    def transforms(self, positions: dict[str, float]) -> list[Transform]:
        """(parent, child, translation, quaternion x y z w) per joint at ``positions``
        (radians or metres by joint name; a joint not given stays at 0): revolute and
        continuous q_origin (axis sin(q/2), cos(q/2)), prismatic xyz + R_origin axis q."""
        out: list[Transform] = []
        for name, kind, parent, child, xyz, origin, axis, rotation in self._plain:
            q = float(positions.get(name, 0.0))
            translation = xyz
            turn = origin
            if kind in ("revolute", "continuous"):
                s = math.sin(0.5 * q)
                turn = _product(origin, (axis[0] * s, axis[1] * s, axis[2] * s,
                                         math.cos(0.5 * q)))
            elif kind == "prismatic":
                translation = tuple(xyz[r] + q * sum(rotation[r][c] * axis[c] for c in range(3))
                                    for r in range(3))
            out.append((parent, child, translation, turn))
        return out
