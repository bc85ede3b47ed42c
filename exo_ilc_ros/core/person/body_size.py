"""A person model's arm scaled to a person's body size (``musculoskeletal.body_size: person``).

MyoSuite's models are one adult each. To a person of body mass, height and sex (the keys
``person.body_mass``, ``person.height``, ``person.sex``), the arm is scaled segment by segment,
as OpenSim's Scale Tool scales a generic model (Delp et al., IEEE TBME 54(11):1940-1950, 2007):

* **The targets** are de Leva's segments of that person (core/arm/body_segments.py, de Leva
  1996): the upper arm's length (shoulder to elbow joint centre) and mass; the forearm with
  the hand, their common centre of mass's distance from the elbow and their mass (the models'
  forearm carries the pruned or welded hand).
* **The upper arm** (the humerus body: its geoms, sites, joint anchors, centre of mass and the
  elbow's place on it) is scaled by L_u = target length / the model's shoulder-elbow distance
  at rest; its mass by M_u = target mass / the model's, its inertia by M_u L_u^2.
* **The forearm** (the forearm body and every body below it) likewise by L_f (centre-of-mass
  distances) and M_f. The bodies above the humerus (torso, shoulder girdle) keep their size.
* **The muscles**: each muscle-tendon unit's optimal fibre length and tendon slack length are
  scaled by the ratio of its length at the rest pose after and before (OpenSim's rule; in
  MuJoCo, the actuator's ``lengthrange``, from which both follow). Its peak isometric force by
  M / r, M the arm's mass ratio and r that length ratio: the force is proportional to the
  physiological cross-section, muscle volume over fibre length, with the volume taken
  proportional to the segments' mass (a constant muscle share of the segment).

Wrapping surfaces and via sites move with their bodies. Joint ranges, the neural drive and
the joints' own damping are left as they are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arm.body_segments import arm_segments
from ..errors import ConfigError
from ..params.config import Config
from .model import ANATOMY, PersonAnatomy, compile_quietly, person_spec, rest_pose

BODY_SIZES = ("model", "person")
"""``musculoskeletal.body_size``: the model's own size, or scaled to the person's keys."""


@dataclass(frozen=True)
class ArmMeasures:
    """A person model's arm at its rest pose, as de Leva measures a person's."""

    upper_arm_length: float
    """m, shoulder centre (the humerus' origin) to the elbow's joint centre."""
    upper_arm_mass: float
    """kg, the humerus body."""
    forearm_com: float
    """m, the elbow's joint centre to the centre of mass of the forearm and everything on it."""
    forearm_mass: float
    """kg, the forearm body and every body below it."""


@dataclass(frozen=True)
class BodySize:
    """The factors that scale a model's arm to a person (1: the model as built)."""

    upper_arm_length: float
    upper_arm_mass: float
    forearm_length: float
    forearm_mass: float
    arm_mass: float
    """The whole arm's mass ratio (the muscles' peak forces scale with it)."""


def measure_arm(model: Any, anatomy: PersonAnatomy) -> ArmMeasures:
    """The arm of a compiled person model at its rest pose (:func:`.model.rest_pose`)."""
    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:] = rest_pose(model, anatomy)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    humerus = model.body(anatomy.upper_arm).id
    forearm = model.body(anatomy.forearm).id
    elbow = np.array(data.xanchor[model.joint(anatomy.elbow_flexion).id])
    return ArmMeasures(
        float(np.linalg.norm(elbow - data.xpos[humerus])), float(model.body_mass[humerus]),
        float(np.linalg.norm(data.subtree_com[forearm] - elbow)),
        float(model.body_subtreemass[forearm]))


def body_size(measures: ArmMeasures, body_mass: float, height: float, sex: str) -> BodySize:
    """The factors that give the arm of ``measures`` de Leva's segments of a person of
    ``body_mass`` (kg), ``height`` (m) and ``sex`` (module docstring)."""
    upper, forearm, hand = arm_segments(body_mass, height, sex)
    lower_mass = forearm.mass + hand.mass
    lower_com = (forearm.mass * forearm.com_distance
                 + hand.mass * (forearm.length + hand.com_distance)) / lower_mass
    arm = (upper.mass + lower_mass) / (measures.upper_arm_mass + measures.forearm_mass)
    return BodySize(upper.length / measures.upper_arm_length,
                    upper.mass / measures.upper_arm_mass,
                    lower_com / measures.forearm_com, lower_mass / measures.forearm_mass, arm)


def _subtree(body: Any) -> list[Any]:
    out = [body]
    for child in body.bodies:
        out += _subtree(child)
    return out


def _scale_place(element: Any, length: float) -> None:
    """A geom's or a site's position, size and ``fromto`` (where given) by ``length``."""
    element.pos = np.asarray(element.pos) * length
    element.size = np.asarray(element.size) * length
    fromto = np.asarray(element.fromto)
    if np.all(np.isfinite(fromto)):
        element.fromto = fromto * length


def _scale_body(body: Any, length: float, mass: float, meshes: dict[str, float]) -> None:
    """One body's own elements and its children's places by ``length``, its inertia by
    ``mass`` (given, or of its geoms)."""
    body.ipos = np.asarray(body.ipos) * length
    body.mass = body.mass * mass
    inertia = mass * length ** 2
    body.inertia = np.asarray(body.inertia) * inertia
    full = np.asarray(body.fullinertia)
    if np.all(np.isfinite(full)):
        body.fullinertia = full * inertia
    for geom in body.geoms:
        _scale_place(geom, length)
        if geom.meshname:
            meshes[geom.meshname] = length
        if not body.explicitinertial:  # its inertia is its geoms': their mass scales by mass
            geom.density = geom.density * mass / length ** 3
            if np.isfinite(geom.mass):
                geom.mass = geom.mass * mass
    for site in body.sites:
        _scale_place(site, length)
    for joint in body.joints:
        joint.pos = np.asarray(joint.pos) * length
    for child in body.bodies:  # where each child sits on this body
        child.pos = np.asarray(child.pos) * length


def _muscle_lengths(model: Any, anatomy: PersonAnatomy) -> dict[str, float]:
    """Every muscle's actuator length at the rest pose (m)."""
    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:] = rest_pose(model, anatomy)
    mujoco.mj_fwdPosition(model, data)
    return {model.actuator(i).name: float(data.actuator_length[i]) for i in range(model.nu)
            if model.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE}


def scale_person(spec: Any, model: Any, anatomy: PersonAnatomy, size: BodySize) -> None:
    """Scale the arm of ``spec`` (an uncompiled person model; ``model``: it compiled, before
    the scaling) in place by ``size`` (module docstring)."""
    import mujoco

    before = _muscle_lengths(model, anatomy)
    meshes: dict[str, float] = {}
    _scale_body(spec.body(anatomy.upper_arm), size.upper_arm_length, size.upper_arm_mass,
                meshes)  # the humerus, and where the elbow sits on it
    for body in _subtree(spec.body(anatomy.forearm)):
        _scale_body(body, size.forearm_length, size.forearm_mass, meshes)
    for mesh in spec.meshes:
        if mesh.name in meshes:
            mesh.scale = np.asarray(mesh.scale) * meshes[mesh.name]
    after = _muscle_lengths(compile_quietly(spec.copy()), anatomy)
    for actuator in spec.actuators:
        if actuator.name not in before or before[actuator.name] <= 0.0:
            continue
        ratio = after[actuator.name] / before[actuator.name]
        actuator.lengthrange = np.asarray(actuator.lengthrange) * ratio
        gain = np.array(actuator.gainprm)
        gain[2] *= size.arm_mass / ratio
        actuator.gainprm = gain
        if actuator.biastype == mujoco.mjtBias.mjBIAS_MUSCLE:
            bias = np.array(actuator.biasprm)
            bias[2] *= size.arm_mass / ratio
            actuator.biasprm = bias


def scaled_person_spec(config: Config) -> Any:
    """The person model of ``config`` (:func:`.model.person_spec`), scaled to the person's
    body size when ``musculoskeletal.body_size`` is ``person``."""
    name = str(config["musculoskeletal.model"])
    if name not in ANATOMY:
        raise ConfigError("musculoskeletal.model", f"no person model {name!r}")
    spec = person_spec(name)
    how = str(config["musculoskeletal.body_size"])
    if how == "model":
        return spec
    if how != "person":
        raise ConfigError("musculoskeletal.body_size", f"one of {', '.join(BODY_SIZES)}, got "
                          f"{how!r}")
    anatomy = ANATOMY[name]
    model = compile_quietly(spec.copy())
    size = body_size(measure_arm(model, anatomy), float(config["person.body_mass"]),
                     float(config["person.height"]), str(config["person.sex"]))
    scale_person(spec, model, anatomy, size)
    return spec
