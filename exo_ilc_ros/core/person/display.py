"""The person as the live view and the bags draw it: a display URDF of the person's bodies
(:func:`person_urdf`), built from the compiled MuJoCo model the plant steps, whose joints are
the person's own MuJoCo joints, so that forward kinematics of the URDF at the person's joint
angles (``/person/joint_states``) puts every body where MuJoCo has it (tested against
``xpos`` / ``xquat``).

* **Frames**: one link ``person/<body>`` per body of the person (every body of the model that
  is not the exoskeleton's), on the root link of the exoskeleton's URDF (``base_link`` for the
  paper's arm) through a fixed joint ``person/placement`` to ``person/world`` (MuJoCo's world,
  where the person's torso is fixed): the inverse of where the exoskeleton's base sits on the
  person (:attr:`~.strapped.StrappedArm.base_position`, misalignment included). So the person
  moves with the simulation, not with the exoskeleton's links: the cuffs are soft and the
  joints misaligned, and the drawing shows it.
* **Joints**: MuJoCo moves a body by its joints in order, each about its anchor (hinge) or
  along its axis (slide), by q - qpos0. Each becomes a URDF ``continuous`` (hinge) or
  ``prismatic`` (slide) joint of the same name from the body's parent (or the previous joint's
  link ``person/<body>/<joint>``) with its origin at the anchor; a fixed joint then takes the
  last one to ``person/<body>``. A body without joints is fixed on its parent.
* **Shapes**: the bones are meshes in MyoSuite's models, which the URDF does not carry. Each
  body is drawn as segments (a cylinder with a sphere at each end, skin-coloured as the
  rigid-body person of ``core/arm/build.py``): from its origin to each child body's origin,
  or, for a body without children, to twice its centre of mass (a forearm's length); as thick
  as a solid cylinder of the body's mass at the density of soft tissue
  (:data:`TISSUE_DENSITY`), within :data:`RADIUS_RANGE`. Segments shorter than
  :data:`MIN_SEGMENT` are not drawn (MyoArm's phantom bodies).

``mujoco`` is not imported here: the functions take the compiled model.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from ..arm.build import PERSON_COLOUR
from ..errors import ModelError

PERSON_PREFIX = "person/"
"""Prefix of the person's frames (links) in the view's TF tree."""
PERSON_WORLD = PERSON_PREFIX + "world"
PLACEMENT_JOINT = PERSON_PREFIX + "placement"
TISSUE_DENSITY = 1050.0
"""kg/m^3: a segment's thickness is that of a solid cylinder of its body's mass at this
density."""
RADIUS_RANGE = (0.006, 0.08)
"""m: the drawn radius is kept within this."""
MIN_SEGMENT = 0.01
"""m: shorter segments are not drawn."""
HINGE, SLIDE = 3, 2
"""MuJoCo's ``mjtJoint`` values of the joints a person may have."""


def person_bodies(model: Any, exo_prefix: str) -> list[int]:
    """The person's body ids (parents before children, as MuJoCo orders them): every body but
    the world and the exoskeleton's (names starting with ``exo_prefix``)."""
    return [b for b in range(1, model.nbody) if not model.body(b).name.startswith(exo_prefix)]


def person_joint_names(model: Any, exo_prefix: str) -> list[str]:
    """The person's joints in qpos order (the names ``/person/joint_states`` carries)."""
    names = []
    for j in range(model.njnt):
        name = str(model.joint(j).name)
        if name.startswith(exo_prefix):
            continue
        if int(model.jnt_type[j]) not in (HINGE, SLIDE):
            raise ModelError(f"person joint {name!r}: only hinge and slide joints are drawn")
        names.append(name)
    return names


def _rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw of a rotation matrix (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = math.asin(max(-1.0, min(1.0, -float(rotation[2, 0]))))
    if abs(float(rotation[2, 0])) < 1.0 - 1e-12:
        roll = math.atan2(float(rotation[2, 1]), float(rotation[2, 2]))
        yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    else:  # gimbal lock: yaw carries the whole turn about z
        roll = 0.0
        yaw = math.atan2(-float(rotation[0, 1]), float(rotation[1, 1]))
    return roll, pitch, yaw


def _quat_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrix of a MuJoCo quaternion (w x y z)."""
    w, x, y, z = (float(v) for v in quat / np.linalg.norm(quat))
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _axis_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _text(values: Any) -> str:
    return " ".join(repr(float(v)) for v in values)


def _joint(robot: ET.Element, name: str, kind: str, parent: str, child: str,
           origin: tuple[np.ndarray, np.ndarray], axis: np.ndarray | None = None) -> None:
    joint = ET.SubElement(robot, "joint", name=name, type=kind)
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    ET.SubElement(joint, "origin", xyz=_text(origin[0]), rpy=_text(_rpy(origin[1])))
    if axis is not None:
        ET.SubElement(joint, "axis", xyz=_text(axis))
    if kind == "prismatic":
        ET.SubElement(joint, "limit", lower="-1", upper="1", effort="0", velocity="0")


def _segments(model: Any, body: int, children: list[int]) -> list[np.ndarray]:
    ends = [np.array(model.body_pos[c]) for c in children]
    if not children and float(model.body_mass[body]) > 0.0:
        ends = [2.0 * np.array(model.body_ipos[body])]
    return [e for e in ends if float(np.linalg.norm(e)) >= MIN_SEGMENT]


def _visuals(link: ET.Element, model: Any, body: int, segments: list[np.ndarray]) -> None:
    """A cylinder and two spheres per segment (module docstring)."""
    length = sum(float(np.linalg.norm(s)) for s in segments)
    if not length:
        return
    radius = math.sqrt(float(model.body_mass[body]) / (TISSUE_DENSITY * math.pi * length))
    radius = min(max(radius, RADIUS_RANGE[0]), RADIUS_RANGE[1])

    def visual(xyz: np.ndarray, rotation: np.ndarray, shape: str, **size: str) -> None:
        element = ET.SubElement(link, "visual")
        ET.SubElement(element, "origin", xyz=_text(xyz), rpy=_text(_rpy(rotation)))
        ET.SubElement(ET.SubElement(element, "geometry"), shape, dict(size))
        material = ET.SubElement(element, "material", name="person")
        ET.SubElement(material, "color", rgba=PERSON_COLOUR)

    for end in segments:
        norm = float(np.linalg.norm(end))
        z = end / norm
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        rotation = np.column_stack([x, np.cross(z, x), z])
        visual(0.5 * end, rotation, "cylinder", radius=repr(radius), length=repr(norm))
        for at in (np.zeros(3), end):
            visual(at, np.eye(3), "sphere", radius=repr(radius))


def person_urdf(model: Any, root_link: str, base_position: np.ndarray,
                base_rotation: np.ndarray, exo_prefix: str) -> str:
    """The person's display URDF (module docstring) from the compiled ``model`` (the
    strapped model, or the person's alone: the same bodies), hung from the exoskeleton's
    ``root_link``, whose frame sits at ``base_position``, ``base_rotation`` in MuJoCo's
    world."""
    robot = ET.Element("robot", name="person")
    ET.SubElement(robot, "link", name=root_link)
    ET.SubElement(robot, "link", name=PERSON_WORLD)
    rotation = np.asarray(base_rotation, dtype=float)
    _joint(robot, PLACEMENT_JOINT, "fixed", root_link, PERSON_WORLD,
           (-rotation.T @ np.asarray(base_position, dtype=float), rotation.T))
    bodies = person_bodies(model, exo_prefix)
    for body in bodies:
        name = PERSON_PREFIX + str(model.body(body).name)
        parent_id = int(model.body_parentid[body])
        parent = PERSON_WORLD if parent_id == 0 else PERSON_PREFIX + str(model.body(parent_id).name)
        origin = (np.array(model.body_pos[body]), _quat_matrix(np.array(model.body_quat[body])))
        for j in range(int(model.body_jntadr[body]),
                       int(model.body_jntadr[body]) + int(model.body_jntnum[body])):
            kind = int(model.jnt_type[j])
            anchor = np.array(model.jnt_pos[j])
            axis = np.array(model.jnt_axis[j])
            ref = float(model.qpos0[model.jnt_qposadr[j]])
            position = origin[0] + origin[1] @ anchor
            turn = origin[1]
            if kind == HINGE:  # MuJoCo turns by q - qpos0: the -qpos0 goes into the origin
                turn = turn @ _axis_matrix(axis, -ref)
            elif kind == SLIDE:
                position = position - ref * (turn @ axis)
            else:
                raise ModelError(f"person joint {model.joint(j).name!r}: only hinge and slide "
                                 "joints are drawn")
            joint = str(model.joint(j).name)
            link = f"{name}/{joint}"
            ET.SubElement(robot, "link", name=link)
            _joint(robot, joint, "continuous" if kind == HINGE else "prismatic", parent, link,
                   (position, turn), axis)
            parent = link
            origin = (-anchor, np.eye(3))
        element = ET.SubElement(robot, "link", name=name)
        _joint(robot, f"{name}/fixed", "fixed", parent, name, origin)
        children = [c for c in bodies if int(model.body_parentid[c]) == body]
        _visuals(element, model, body, _segments(model, body, children))
    return ET.tostring(robot, encoding="unicode")
