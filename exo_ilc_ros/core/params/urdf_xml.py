"""A URDF's XML as plain records, with the standard library's parser: its links' inertials and
its joints (type, origin, axis, limits, dynamics), every number checked, and ``package://``
resolved the ROS way (``ament_index_python``) where the package is installed; the moving joints
of a chain (:func:`chain_joints`: the config needs their names). The chain the kernels take is
built from them by :mod:`exo_ilc_ros.core.arm.urdf_chain`. Errors (:class:`UrdfError`) name the
file and the element."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ModelError

MOVING_TYPES = ("revolute", "continuous")
LOCKABLE_TYPES = ("revolute", "continuous", "prismatic")
KNOWN_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


class UrdfError(ModelError):
    """The URDF cannot give the chain asked for; the message names the file and the element."""


class UrdfKeyError(UrdfError):
    """A URDF problem one config key fixes: :attr:`key` names it (``model.base_link``,
    ``model.tip_link``, ``model.locked_joints``)."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


@dataclass(frozen=True)
class Inertial:
    mass: float
    rotation: np.ndarray
    origin: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    type: str
    parent: str
    child: str
    rotation: np.ndarray
    origin: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float
    effort: float
    velocity: float
    damping: float
    friction: float


def resolve_package_uri(uri: str) -> Path:
    """``package://name/rest`` to a path the ROS way (the package's share directory from
    ``ament_index_python``); :class:`UrdfError` when it cannot be."""
    rest = uri[len("package://"):]
    package, _, relative = rest.partition("/")
    try:
        from ament_index_python.packages import (  # optional: a ROS install
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:
        raise UrdfError(f"{uri}: cannot resolve package://: ament_index_python is not "
                        "installed (source a ROS 2 install, or give a file path)") from None
    try:
        share = get_package_share_directory(package)
    except PackageNotFoundError:
        raise UrdfError(f"{uri}: package {package!r} is not installed (not in the ament "
                        "index); source its workspace or give a file path") from None
    except OSError:  # AMENT_PREFIX_PATH unset: no ROS environment sourced
        raise UrdfError(f"{uri}: cannot find package {package!r}: AMENT_PREFIX_PATH is not "
                        "set (source a ROS 2 install or workspace, or give a file path)"
                        ) from None
    return Path(share) / relative


def rpy_rotation(rpy: np.ndarray) -> np.ndarray:
    """The URDF's ``rpy``: R = Rz(yaw) Ry(pitch) Rx(roll) (fixed axes x, y, z)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y),
                              math.sin(y))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit vector ``axis`` (Rodrigues)."""
    x, y, z = (float(v) for v in axis)
    c, s = math.cos(angle), math.sin(angle)
    v = 1.0 - c
    return np.array([[c + x * x * v, x * y * v - z * s, x * z * v + y * s],
                     [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
                     [z * x * v - y * s, z * y * v + x * s, c + z * z * v]])


def _floats(text: str | None, count: int, default: tuple[float, ...], where: str
            ) -> np.ndarray:
    if text is None:
        return np.array(default, dtype=float)
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        raise UrdfError(f"{where}: {text!r} is not {count} numbers") from None
    if len(values) != count:
        raise UrdfError(f"{where}: {text!r} is not {count} numbers")
    return np.array(values, dtype=float)


def _number(element: ET.Element | None, name: str, default: float, where: str) -> float:
    if element is None or element.get(name) is None:
        return default
    try:
        return float(element.get(name, ""))
    except ValueError:
        raise UrdfError(f"{where}: {name}={element.get(name)!r} is not a number") from None


def _origin(element: ET.Element | None, where: str) -> tuple[np.ndarray, np.ndarray]:
    if element is None:
        return np.eye(3), np.zeros(3)
    xyz = _floats(element.get("xyz"), 3, (0.0, 0.0, 0.0), f"{where} <origin xyz>")
    rpy = _floats(element.get("rpy"), 3, (0.0, 0.0, 0.0), f"{where} <origin rpy>")
    return rpy_rotation(rpy), xyz


def read_urdf_text(source: str | Path) -> tuple[str, str]:
    """(text, where) of a path, a ``package://`` URI or URDF text."""
    if isinstance(source, str) and source.lstrip().startswith("<"):
        return source, "<text>"
    path = resolve_package_uri(str(source)) if str(source).startswith("package://") \
        else Path(source)
    try:
        return path.read_text(encoding="utf-8"), str(path)
    except FileNotFoundError:
        raise UrdfError(f"{path}: no such URDF file") from None
    except OSError as exc:
        raise UrdfError(f"{path}: cannot read the URDF ({exc.strerror})") from None


def parse_urdf(text: str, where: str
               ) -> tuple[str, dict[str, Inertial | None], dict[str, UrdfJoint]]:
    """The robot's name, every link's inertial (None: none given) and every joint, by name, of
    the URDF ``text`` read from ``where`` (named in every error)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise UrdfError(f"{where}: not well-formed XML ({exc})") from None
    if root.tag != "robot":
        raise UrdfError(f"{where}: the root element is <{root.tag}>, not <robot>")
    links: dict[str, Inertial | None] = {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise UrdfError(f"{where}: a <link> has no name")
        if name in links:
            raise UrdfError(f"{where}: link {name!r} is defined twice")
        inertial = link.find("inertial")
        if inertial is None:
            links[name] = None
            continue
        at = f"{where}: link {name!r} <inertial>"
        rotation, origin = _origin(inertial.find("origin"), at)
        mass = _number(inertial.find("mass"), "value", 0.0, f"{at} <mass>")
        element = inertial.find("inertia")
        i = {k: _number(element, k, 0.0, f"{at} <inertia>")
             for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        tensor = np.array([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]],
                           [i["ixz"], i["iyz"], i["izz"]]])
        if mass < 0.0:
            raise UrdfError(f"{at}: negative mass {mass}")
        links[name] = Inertial(mass, rotation, origin, tensor)
    joints: dict[str, UrdfJoint] = {}
    for joint in root.findall("joint"):
        name = joint.get("name") or ""
        at = f"{where}: joint {name!r}"
        if not name:
            raise UrdfError(f"{where}: a <joint> has no name")
        if name in joints:
            raise UrdfError(f"{at} is defined twice")
        kind = joint.get("type", "")
        if kind not in KNOWN_TYPES:
            raise UrdfError(f"{at}: unknown type {kind!r} (one of {', '.join(KNOWN_TYPES)})")
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None or not parent.get("link") or not child.get("link"):
            raise UrdfError(f"{at}: needs <parent link=...> and <child link=...>")
        for end in (parent.get("link", ""), child.get("link", "")):
            if end not in links:
                raise UrdfError(f"{at}: link {end!r} is not defined")
        rotation, origin = _origin(joint.find("origin"), at)
        axis_element = joint.find("axis")
        axis = _floats(None if axis_element is None else axis_element.get("xyz"), 3,
                       (1.0, 0.0, 0.0), f"{at} <axis xyz>")
        norm = float(np.linalg.norm(axis))
        if kind in LOCKABLE_TYPES and norm == 0.0:
            raise UrdfError(f"{at}: <axis xyz> is zero")
        limit, dynamics = joint.find("limit"), joint.find("dynamics")
        joints[name] = UrdfJoint(
            name, kind, parent.get("link", ""), child.get("link", ""), rotation, origin,
            axis / norm if norm > 0.0 else axis,
            _number(limit, "lower", -math.inf, f"{at} <limit>"),
            _number(limit, "upper", math.inf, f"{at} <limit>"),
            _number(limit, "effort", math.inf, f"{at} <limit>"),
            _number(limit, "velocity", math.inf, f"{at} <limit>"),
            _number(dynamics, "damping", 0.0, f"{at} <dynamics>"),
            _number(dynamics, "friction", 0.0, f"{at} <dynamics>"))
    return root.get("name", ""), links, joints


def checked_locks(locked: dict[str, float], joints: Mapping[str, UrdfJoint],
                   where: str) -> dict[str, float]:
    """``locked`` if every name is a lockable joint of the URDF at a finite value."""
    for name, value in locked.items():
        if name not in joints:
            raise UrdfError(f"{where}: locked joint {name!r} is not in the URDF")
        if joints[name].type not in LOCKABLE_TYPES:
            raise UrdfError(f"{where}: locked joint {name!r} is {joints[name].type}; only "
                            f"{', '.join(LOCKABLE_TYPES)} joints can be locked")
        if not math.isfinite(value):
            raise UrdfError(f"{where}: locked joint {name!r}: value {value} is not finite")
    return locked

def joint_tree(links: Mapping[str, Inertial | None], joints: Mapping[str, UrdfJoint], where: str
          ) -> tuple[dict[str, UrdfJoint], dict[str, list[UrdfJoint]]]:
    """Each link's parent joint and each link's child joints (an error if a link has two
    parents: not a tree)."""
    parent_joint: dict[str, UrdfJoint] = {}
    for joint in joints.values():
        if joint.child in parent_joint:
            raise UrdfError(f"{where}: link {joint.child!r} has two parent joints "
                            f"({parent_joint[joint.child].name!r}, {joint.name!r}): not a tree")
        parent_joint[joint.child] = joint
    children: dict[str, list[UrdfJoint]] = {name: [] for name in links}
    for joint in joints.values():
        children[joint.parent].append(joint)
    return parent_joint, children

def chain_path(base_link: str, tip_link: str, links: Mapping[str, Inertial | None],
          parent_joint: Mapping[str, UrdfJoint], where: str) -> list[UrdfJoint]:
    """The joints from ``base_link`` down to ``tip_link``, in order."""
    for end, role in ((base_link, "base"), (tip_link, "tip")):
        if end not in links:
            raise UrdfError(f"{where}: {role} link {end!r} is not a link of the URDF")
    path: list[UrdfJoint] = []
    link = tip_link
    while link != base_link:
        above = parent_joint.get(link)
        if above is None:
            raise UrdfError(f"{where}: tip link {tip_link!r} is not in the chain below base "
                            f"link {base_link!r} (walking up from the tip reached the root "
                            f"{link!r})")
        path.append(above)
        link = above.parent
    path.reverse()
    return path

def moving_joints(path: list[UrdfJoint], locked: Mapping[str, float], base_link: str,
                   tip_link: str, where: str) -> list[UrdfJoint]:
    """The path's revolute and continuous joints that are not locked (an error for a
    prismatic, floating or planar joint on it, or for none at all)."""
    moving = []
    for joint in path:
        if joint.name in locked or joint.type == "fixed":
            continue
        if joint.type in MOVING_TYPES:
            moving.append(joint)
        elif joint.type == "prismatic":
            raise UrdfError(f"{where}: joint {joint.name!r} between {base_link!r} and "
                            f"{tip_link!r} is prismatic; only revolute and continuous joints "
                            "are supported (lock it at a value)")
        else:
            raise UrdfError(f"{where}: joint {joint.name!r} between {base_link!r} and "
                            f"{tip_link!r} is {joint.type}: a floating or planar base is not "
                            "a fixed-base arm (choose a base link below it)")
    if not moving:
        raise UrdfError(f"{where}: no revolute or continuous joint between {base_link!r} and "
                        f"{tip_link!r}")
    return moving


def chain_ends(base_link: str, tip_link: str, links: Mapping[str, Inertial | None],
               parent_joint: Mapping[str, UrdfJoint], children: Mapping[str, list[UrdfJoint]],
               locked: Mapping[str, float], where: str) -> tuple[str, str]:
    """(base link, tip link) with an empty ``base_link`` the URDF's root link and an empty
    ``tip_link`` the last link every chain below the base with the most moving joints passes
    through: the single leaf, or the link where only fixed, locked or prismatic joints branch
    off (a gripper's fingers, tool frames). :class:`UrdfKeyError` naming the key when the URDF
    does not say which (several roots; chains that branch at a moving joint: two arms)."""
    if not base_link:
        roots = [name for name in links if name not in parent_joint]
        if len(roots) != 1:
            raise UrdfKeyError("model.base_link", f"{where}: model.base_link is empty (the "
                               f"URDF's root) and the URDF has {len(roots)} root links "
                               f"({', '.join(map(repr, roots))}): name the base link")
        base_link = roots[0]
    if not tip_link and base_link in links:
        tip_link = _only_tip(base_link, children, locked, where)
    return base_link, tip_link


def _only_tip(base_link: str, children: Mapping[str, list[UrdfJoint]],
              locked: Mapping[str, float], where: str) -> str:
    """The tip of :func:`chain_ends` for an empty ``model.tip_link``."""
    moves = {base_link: 0}  # moving joints from the base to each link
    paths: list[list[str]] = []  # from the base to each leaf
    stack = [[base_link]]
    while stack:
        path = stack.pop()
        below = children[path[-1]]
        if not below:
            paths.append(path)
        for joint in below:
            moving = joint.type in MOVING_TYPES and joint.name not in locked
            moves[joint.child] = moves[path[-1]] + int(moving)
            stack.append([*path, joint.child])
    most = max(moves[path[-1]] for path in paths)
    if most == 0:
        raise UrdfKeyError("model.tip_link", f"{where}: model.tip_link is empty and no "
                           f"revolute or continuous joint (not locked) is below the base link "
                           f"{base_link!r}")
    longest = [path for path in paths if moves[path[-1]] == most]
    shared = longest[0]
    for path in longest[1:]:
        common = 0
        while common < min(len(shared), len(path)) and shared[common] == path[common]:
            common += 1
        shared = shared[:common]
    if moves[shared[-1]] < most:
        ends = sorted(path[-1] for path in longest)
        raise UrdfKeyError("model.tip_link", f"{where}: model.tip_link is empty and the URDF "
                           f"branches below link {shared[-1]!r} into {len(ends)} chains of "
                           f"{most} moving joints from the base link {base_link!r} (to "
                           f"{', '.join(map(repr, ends))}): name the tip link")
    return shared[-1]


def check_moving_bodies(moving: list[UrdfJoint], children: Mapping[str, list[UrdfJoint]],
                        locked: Mapping[str, float], base_link: str, tip_link: str,
                        where: str) -> None:
    """:class:`UrdfKeyError` for a joint that could move a link of a moving body: beyond the
    tip (key ``model.tip_link``), or on a branch off the chain after its first moving joint
    (``model.locked_joints``). Every such joint must be fixed or locked: the chain has no
    degree of freedom for it."""
    on_chain = {j.name for j in moving}
    for joint in moving:
        stack = [(joint.child, joint.child == tip_link)]
        while stack:
            link, beyond = stack.pop()
            for below in children[link]:
                if below.name in on_chain:
                    continue  # the next moving body
                if below.type == "fixed" or below.name in locked:
                    stack.append((below.child, beyond or below.child == tip_link))
                elif beyond:
                    raise UrdfKeyError(
                        "model.tip_link", f"{where}: joint {below.name!r} ({below.type}) moves "
                        f"link {below.child!r} beyond the tip link {tip_link!r}: lock it "
                        "(model.locked_joints) or choose a tip beyond it (model.tip_link)")
                else:
                    raise UrdfKeyError(
                        "model.locked_joints", f"{where}: joint {below.name!r} ({below.type}) "
                        f"moves link {below.child!r} off the chain {base_link!r} -> "
                        f"{tip_link!r} (it hangs from link {link!r}, which moves): lock it "
                        "(model.locked_joints) or choose another tip (model.tip_link)")


def resolved_chain(text: str, where: str, base_link: str, tip_link: str,
                   locked: Mapping[str, float]) -> tuple[str, str, list[UrdfJoint]]:
    """(base link, tip link, moving joints) of the URDF ``text`` read from ``where``: the ends
    of :func:`chain_ends` (an empty one found in the URDF) and the moving joints (revolute,
    continuous, not locked) between them in chain order; the errors of :func:`moving_joints`
    and :func:`check_moving_bodies`."""
    _, links, joints = parse_urdf(text, where)
    locks = checked_locks(dict(locked), joints, where)
    parent_joint, children = joint_tree(links, joints, where)
    base, tip = chain_ends(base_link, tip_link, links, parent_joint, children, locks, where)
    moving = moving_joints(chain_path(base, tip, links, parent_joint, where), locks, base, tip,
                           where)
    check_moving_bodies(moving, children, locks, base, tip, where)
    return base, tip, moving


def chain_joints(text: str, where: str, base_link: str, tip_link: str,
                 locked: Mapping[str, float]) -> list[UrdfJoint]:
    """The moving joints of :func:`resolved_chain`, in chain order."""
    return resolved_chain(text, where, base_link, tip_link, locked)[2]
