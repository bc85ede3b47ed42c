"""MuJoCo from the same URDF as :mod:`exo_ilc_ros.core.arm.urdf_chain`, through ``mujoco.MjSpec``
(MuJoCo's own URDF parser, so its dynamics are an independent reading of the file).

Before parsing, the URDF is cut to the chain :func:`read_urdf_chain` keeps: ``<visual>``,
``<collision>`` (meshes: collision ``.dae`` files do not load), ``<gazebo>`` and
``<transmission>`` elements removed; links above the base link, dropped branches and anything
not merged into the chain removed (the base link becomes MuJoCo's root, fixed to the world);
locked joints made fixed at their locked value. Then, on the spec:

* one motor per moving joint (``<joint>_motor``: force = ctrl, unlimited), in the chain's order;
* RK4 at the given time step (``integration_step``, the method and step of our plant), contacts
  off, gravity the chain's (the root's, (0, 0, -g) or a vector, in the base link's frame);
* joint limits off (our plant has none; references are to be checked against the URDF's limits
  before a run);
* joint effects handled explicitly, as our model handles them: the rigid-body dynamics only.
  MuJoCo's URDF parser turns ``<dynamics damping friction>`` into joint ``damping`` and
  ``frictionloss``; both are reset here, and ``armature`` is zero (a URDF has none; our
  kernels neither), so that MuJoCo's mass matrix and bias are exactly what our kernels compute
  (tested). With ``damping=True`` the URDF's viscous damping b is put back as MuJoCo's joint
  damping, the torque -b qdot; with ``friction=True`` the URDF's Coulomb friction F is applied
  as the explicit smooth torque -F tanh(qdot / v_s) (``friction_velocity`` v_s), added to
  MuJoCo's passive force at every RK4 stage (:class:`SmoothFriction`), never as
  ``frictionloss`` (a constraint, not a smooth torque). Both are what our plant adds with
  ``model.urdf_joint_dynamics: apply`` (core/loop/patient.py's passive forces), so one period
  equals ours to rounding (tested on the Panda).

``mujoco`` is imported only when a model is built.
"""

from __future__ import annotations

import contextlib
import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ModelError
from ..params.urdf_xml import UrdfError, axis_rotation, read_urdf_text, rpy_rotation
from .model import Gravity
from .urdf_chain import UrdfChain, read_urdf_chain

STRIPPED = ("visual", "collision")
"""Link elements removed before MuJoCo parses the URDF."""
STRIPPED_TOP = ("gazebo", "transmission")


def _rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """The URDF's rpy of a rotation R = Rz(yaw) Ry(pitch) Rx(roll)."""
    pitch = math.asin(max(-1.0, min(1.0, -float(rotation[2, 0]))))
    if abs(math.cos(pitch)) > 1e-12:
        roll = math.atan2(float(rotation[2, 1]), float(rotation[2, 2]))
        yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    else:  # gimbal lock: all of the rotation in yaw
        roll = 0.0
        yaw = math.atan2(-float(rotation[0, 1]), float(rotation[1, 1]))
    return roll, pitch, yaw


def _floats(text: str | None, default: str) -> np.ndarray:
    return np.array([float(v) for v in (text or default).split()])


def chain_urdf(text: str, chain: UrdfChain, shapes: bool = False) -> str:
    """The URDF ``text`` cut to ``chain`` (module docstring): what MuJoCo parses; with
    ``shapes`` the links keep their ``<visual>`` and ``<collision>`` (what a viewer draws of
    the chain, ``exo-ilc urdf``)."""
    root = ET.fromstring(text)
    kept = set(chain.link_poses)
    locked = dict(chain.locked)
    for tag in STRIPPED_TOP:
        for element in root.findall(tag):
            root.remove(element)
    for link in root.findall("link"):
        if link.get("name") not in kept:
            root.remove(link)
            continue
        for tag in () if shapes else STRIPPED:
            for element in link.findall(tag):
                link.remove(element)
    for joint in root.findall("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        ends = (None if parent is None else parent.get("link"),
                None if child is None else child.get("link"))
        if ends[0] not in kept or ends[1] not in kept:
            root.remove(joint)
            continue
        name = joint.get("name", "")
        if name not in locked:
            continue
        origin = joint.find("origin")
        if origin is None:
            origin = ET.SubElement(joint, "origin")
        rotation = rpy_rotation(_floats(origin.get("rpy"), "0 0 0"))
        xyz = _floats(origin.get("xyz"), "0 0 0")
        axis_element = joint.find("axis")
        axis = _floats(None if axis_element is None else axis_element.get("xyz"), "1 0 0")
        axis = axis / np.linalg.norm(axis)
        value = locked[name]
        if joint.get("type") == "prismatic":
            xyz = xyz + rotation @ (value * axis)
        else:
            rotation = rotation @ axis_rotation(axis, value)
        origin.set("xyz", " ".join(repr(float(v)) for v in xyz))
        origin.set("rpy", " ".join(repr(v) for v in _rpy(rotation)))
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "dynamics", "mimic", "safety_controller", "calibration"):
            for element in joint.findall(tag):
                joint.remove(element)
    return ET.tostring(root, encoding="unicode")


def mujoco_model(source: str | Path, base_link: str, tip_link: str,
                 locked: Mapping[str, float] | None = None, timestep: float = 0.001,
                 damping: bool = False, gravity: Gravity = 9.81
                 ) -> tuple[Any, UrdfChain]:
    """(MuJoCo's compiled model, our chain) of the URDF at ``source`` (module docstring)."""
    import mujoco

    chain = read_urdf_chain(source, base_link, tip_link, locked, gravity)
    text, where = read_urdf_text(source)
    try:
        spec = mujoco.MjSpec.from_string(chain_urdf(text, chain))
    except ValueError as exc:
        raise UrdfError(f"{where}: MuJoCo cannot parse the chain's URDF: {exc}") from None
    spec.option.timestep = float(timestep)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_RK4
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    spec.option.gravity = chain.gravity
    joints = {j.name: j for j in spec.joints}
    if set(joints) != set(chain.joint_names):
        raise UrdfError(f"{where}: MuJoCo's joints {sorted(joints)} are not the chain's "
                        f"{list(chain.joint_names)}")
    for i, name in enumerate(chain.joint_names):
        joint = joints[name]
        joint.damping = [float(chain.damping[i]) if damping else 0.0, 0.0, 0.0]
        joint.frictionloss = 0.0
        joint.armature = 0.0
        joint.stiffness = [0.0, 0.0, 0.0]
        joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        spec.add_actuator(name=f"{name}_motor", target=name,
                          trntype=mujoco.mjtTrn.mjTRN_JOINT)
    try:
        model = spec.compile()
    except ValueError as exc:
        raise UrdfError(f"{where}: MuJoCo cannot compile the chain {base_link!r} -> "
                        f"{tip_link!r}: {exc}") from None
    order = [model.joint(j).name for j in range(model.njnt)]
    if order != list(chain.joint_names) or model.nv != chain.dof:
        raise UrdfError(f"{where}: MuJoCo ordered the joints {order}, not "
                        f"{list(chain.joint_names)}")
    return model, chain



def substeps_per_period(period: float, timestep: float,
                        error: type[ModelError] = ModelError) -> int:
    """MuJoCo steps of ``timestep`` per control ``period``; ``error`` if the step does not
    divide the period (both MuJoCo plants check it here)."""
    ratio = period / timestep
    if abs(ratio - round(ratio)) > 1e-9 * ratio:
        raise error(f"the MuJoCo time step {timestep:g} s must divide the control "
                    f"period {period:g} s")
    return int(round(ratio))

class SmoothFriction:
    """The explicit Coulomb torque -F tanh(qdot / v_s) per joint, added to MuJoCo's passive
    force (``qfrc_passive``) through ``mjcb_passive`` at every evaluation of the dynamics (each
    RK4 stage), the form of our plant's (:func:`..arm.joint_forces.passive_effort_into`).
    MuJoCo's callback is global: it is installed only inside ``with`` (one model's steps) and
    the previous one put back."""

    def __init__(self, friction: np.ndarray, velocity: float) -> None:
        self.friction = np.asarray(friction, dtype=float)
        self.inverse_velocity = 1.0 / float(velocity)
        self._previous: Any = None

    def __call__(self, model: Any, data: Any) -> None:
        data.qfrc_passive[:] -= self.friction * np.tanh(data.qvel * self.inverse_velocity)

    def __enter__(self) -> SmoothFriction:
        import mujoco

        self._previous = mujoco.get_mjcb_passive()
        mujoco.set_mjcb_passive(self)
        return self

    def __exit__(self, *exc: object) -> None:
        import mujoco

        mujoco.set_mjcb_passive(self._previous)
        self._previous = None


class MujocoUrdfArm:
    """The URDF's chain in MuJoCo (:func:`mujoco_model`), stepped one control period at a time
    with the effort held, and MuJoCo's joint-space inertia and bias for checks. ``damping``,
    ``friction``: the URDF's viscous damping and Coulomb friction applied (module docstring;
    ``friction_velocity`` v_s of the smooth Coulomb torque)."""

    def __init__(self, source: str | Path, base_link: str, tip_link: str,
                 locked: Mapping[str, float] | None = None, timestep: float = 0.001,
                 period: float = 0.01, damping: bool = False,
                 gravity: Gravity = 9.81,
                 friction: bool = False, friction_velocity: float = 0.1) -> None:
        import mujoco

        self._mujoco = mujoco
        self.substeps = substeps_per_period(period, timestep, UrdfError)
        self.model, self.chain = mujoco_model(source, base_link, tip_link, locked, timestep,
                                              damping, gravity)
        self.data: Any = mujoco.MjData(self.model)
        self._mass = np.zeros((self.chain.dof, self.chain.dof))
        self.friction: SmoothFriction | None = \
            SmoothFriction(self.chain.friction, friction_velocity) \
            if friction and np.any(self.chain.friction != 0.0) else None
        """The explicit Coulomb torque (None: not applied)."""

    def set_state(self, q: Sequence[float], qd: Sequence[float]) -> None:
        """Put the arm at (q, qdot), no effort applied."""
        self.data.qpos[:] = q
        self.data.qvel[:] = qd
        self.data.ctrl[:] = 0.0
        with self._passive():
            self._mujoco.mj_forward(self.model, self.data)

    def step(self, effort: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Hold ``effort`` over one control period; (q, qdot) after it."""
        self.data.ctrl[:] = effort
        with self._passive():
            for _ in range(self.substeps):
                self._mujoco.mj_step(self.model, self.data)
        return np.array(self.data.qpos), np.array(self.data.qvel)

    def _passive(self) -> contextlib.AbstractContextManager[object]:
        return contextlib.nullcontext() if self.friction is None else self.friction

    def inertia_and_bias(self, q: Sequence[float], qd: Sequence[float]
                         ) -> tuple[np.ndarray, np.ndarray]:
        """MuJoCo's a(q) (``mj_fullM``) and bias c(q, qdot) (``qfrc_bias``: Coriolis,
        centrifugal and gravity) at (q, qdot). Leaves the arm at that state."""
        self.set_state(q, qd)
        self._mujoco.mj_fullM(self.model, self.data, self._mass)  # the 4.x signature
        return self._mass.copy(), np.array(self.data.qfrc_bias)

    def passive_force(self) -> np.ndarray:
        """MuJoCo's passive joint torque at the current state (``qfrc_passive``: -b qdot with
        ``damping``, -F tanh(qdot / v_s) with ``friction``)."""
        return np.array(self.data.qfrc_passive)
