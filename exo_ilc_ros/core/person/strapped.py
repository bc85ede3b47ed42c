"""The exoskeleton strapped to a person with muscles, in one MuJoCo model, stepped one control
period at a time (:class:`StrappedArm`, the interface of :class:`~..loop.stepper.PlantStepper`).

**Composition** (``mujoco.MjSpec``): the person of :func:`.model.person_spec` (MyoArm or the
elbow model, its torso fixed to the world), and the exoskeleton generated from the plant's
:class:`~..arm.model.ArmModel` by :func:`~..sim.mujoco_arm.arm_mjcf` (the paper's cone arm or
any URDF chain, masses scaled by 1 + ``mass_uncertainty``: :func:`~..arm.build.build_plant`),
attached to the world at a frame that puts the exoskeleton's joints on the person's:

* at the exoskeleton's start pose x_d(0) (where every trial starts; zero for the paper's arm
  and the shipped person configs), the anchor of its shoulder joint
  (``strapping.shoulder_joint``) is on the person's shoulder centre (the humerus' origin,
  on the glenohumeral joint of :data:`.model.ANATOMY`), the line from it to the anchor of its
  elbow joint (``strapping.elbow_joint``) runs along the person's humerus (shoulder centre to
  elbow centre at the person's rest pose), and its elbow axis is the person's elbow flexion
  axis (made normal to the humerus). So the exoskeleton's shoulder and elbow move with the
  person's shoulder elevation and elbow flexion; a link longer or shorter than the humerus
  leaves its elbow off the person's (:attr:`StrappedArm.elbow_offset`).
* ``strapping.misalignment.offset`` (mm) and ``.rotation`` (deg, x-y-z about the
  exoskeleton's base axes, turned about the shoulder centre) then move the exoskeleton away
  from that fit, as a badly worn exoskeleton sits.

**Cuffs**: an upper-arm cuff (``strapping.upper_arm_cuff``, m from the shoulder centre along
the humerus) on the exoskeleton's body of the shoulder joint and a forearm cuff
(``strapping.forearm_cuff``, m from the elbow centre towards the forearm's centre of mass) on
the body of the elbow joint. Each is a linear spring-damper in six directions between a frame
on the exoskeleton's link and the frame on the person's bone where it was strapped (the two
coincide at the rest pose: no preload): force -K x - B v, torque -K_r theta - B_r omega, in the
cuff's frame (x: the elbow axis, mediolateral; y: anteroposterior; z: along the limb), x and
theta the exoskeleton's displacement and rotation (axis-angle) from the person's. The stiffness
defaults are the linear fits of Schiebl et al., "Quantification of the Mechanical Properties
in the Human-Exoskeleton Upper Arm Interface ...", Sensors 25(15):4605 (2025), Appendix
B.1 (subject-group regressions, the mean of both directions: 3.15, 3.7, 2.25 N/mm; 0.21, 0.185,
0.035 N m/deg), taken for the forearm cuff too (only the upper arm was measured). The damping
is not from a measurement: no published damping of an arm cuff was found here; the defaults
are chosen (about 0.3 of critical damping for a 1 kg segment) and flagged as such in the
schema. The forces are explicit (computed at each MuJoCo step from the step's state, applied
as ``xfrc_applied`` by :func:`cuff_forces_into`): the exact N/m and N s/m of the keys, not
MuJoCo's mass-normalised soft constraints.

**Integration**: ``implicitfast`` at ``musculoskeletal.timestep`` (MyoSuite's own 2 ms by
default), the step split (``mj_step1``, cuff forces and muscle controls from the fresh
kinematics, ``mj_step2``). Contacts are off. The muscles take their controls from a
:class:`~.model.MuscleDrive` called at every step (None: passive, zero excitation).

**The start of a trial**: the exoskeleton at x_d(0), the person first at its rest pose, then
``musculoskeletal.settle_time`` of simulated time with the exoskeleton held there, so the
person hangs in the cuffs at rest; that state is kept and every trial (:meth:`reset`) starts
from it, so the trials are repeatable (and the graph's plant, which steps this same class,
gives the in-process trials: to 1e-9 rad tested, to 6e-16 rad measured).

The learning law sees only the exoskeleton's joints (:attr:`position`, :attr:`velocity`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.build import build_plant
from ..arm.mujoco_urdf import substeps_per_period
from ..errors import ConfigError, ModelError
from ..loop.plant import clamp_counted
from ..params.config import Config
from ..sim.mujoco_arm import arm_mjcf
from .body_size import scaled_person_spec
from .cuffs import CUFFS
from .display import person_joint_names, person_urdf
from .model import ANATOMY, MuscleDrive, compile_quietly, muscle_names, rest_pose

EXO_PREFIX = "exo_"
"""Prefix of the exoskeleton's elements in the composed model."""


@dataclass(frozen=True)
class CuffLaw:
    """The spring-damper of a cuff, per axis of its frame (x mediolateral, y anteroposterior,
    z along the limb)."""

    stiffness: np.ndarray
    """N/m."""
    damping: np.ndarray
    """N s/m."""
    rotational_stiffness: np.ndarray
    """N m/rad."""
    rotational_damping: np.ndarray
    """N m s/rad."""

    @classmethod
    def from_config(cls, config: Config) -> CuffLaw:
        def vector(key: str) -> np.ndarray:
            return np.asarray(config[f"strapping.{key}"], dtype=float)

        return cls(vector("stiffness"), vector("damping"), vector("rotational_stiffness"),
                   vector("rotational_damping"))


def _basis(along: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The rotation whose columns are (x, y, z): z = -along (the limb hangs along -z), x =
    ``axis`` made normal to z, y = z x x."""
    z = -along / np.linalg.norm(along)
    x = axis - np.dot(axis, z) * z
    norm = np.linalg.norm(x)
    if norm < 1e-6:
        raise ModelError("the elbow axis runs along the upper arm: no frame to place the "
                         "exoskeleton by")
    x = x / norm
    return np.column_stack([x, np.cross(z, x), z])


def _euler_xyz(degrees: np.ndarray) -> np.ndarray:
    """Rx Ry Rz of the angles (deg), intrinsic x-y-z."""
    out = np.eye(3)
    for k, angle in enumerate(np.radians(degrees)):
        c, s = np.cos(angle), np.sin(angle)
        i, j = (k + 1) % 3, (k + 2) % 3
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        out = out @ r
    return out


def _quat(rotation: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rotation).reshape(9))
    return q


def _joint_frame(model: Any, data: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    joint = model.joint(name).id
    return np.array(data.xanchor[joint]), np.array(data.xaxis[joint])


class StrappedArm:
    """The exoskeleton strapped to the person (module docstring), one control period at a time
    with the effort held and clamped (as :class:`~..loop.stepper.PlantStepper`)."""

    def __init__(self, config: Config, start: np.ndarray,
                 drive: Callable[[Config, Any], MuscleDrive | None] | None = None) -> None:
        import mujoco

        self._mujoco = mujoco
        name = str(config["musculoskeletal.model"])
        if name not in ANATOMY:
            raise ConfigError("musculoskeletal.model", f"no person model {name!r}")
        self.anatomy = ANATOMY[name]
        self.joint_names = list(config["joint_names"])
        n = len(self.joint_names)
        timestep = float(config["musculoskeletal.timestep"])
        self.substeps = substeps_per_period(float(config["control.period"]), timestep)
        self.limit = np.asarray(config["control.effort_limit"], dtype=float)
        self.law = CuffLaw.from_config(config)
        self.drive: MuscleDrive | None = None
        """The muscles' controls at every step (None: passive)."""
        exo_xml = arm_mjcf(build_plant(config), self.joint_names, timestep)
        exo = mujoco.MjSpec.from_string(exo_xml)
        shoulder = str(config["strapping.shoulder_joint"]) or self.joint_names[0]
        elbow = str(config["strapping.elbow_joint"]) or self.joint_names[-1]
        for key, joint in (("strapping.shoulder_joint", shoulder),
                           ("strapping.elbow_joint", elbow)):
            if joint not in self.joint_names:
                raise ConfigError(key, f"{joint!r} is not one of joint_names "
                                  f"{self.joint_names}")
        person = scaled_person_spec(config)
        person.option.timestep = timestep
        person.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        alone = compile_quietly(person)
        rest = rest_pose(alone, self.anatomy)
        alone_data = mujoco.MjData(alone)
        alone_data.qpos[:] = rest
        mujoco.mj_kinematics(alone, alone_data)
        p_shoulder = np.array(alone_data.xpos[alone.body(self.anatomy.upper_arm).id])
        p_elbow, elbow_axis = _joint_frame(alone, alone_data, self.anatomy.elbow_flexion)
        forearm_com = np.array(alone_data.xipos[alone.body(self.anatomy.forearm).id])
        exo_alone = exo.compile()
        exo_data = mujoco.MjData(exo_alone)
        for j, joint in enumerate(self.joint_names):  # fitted where every trial starts
            exo_data.qpos[exo_alone.jnt_qposadr[exo_alone.joint(joint).id]] = start[j]
        mujoco.mj_kinematics(exo_alone, exo_data)
        e_shoulder, _ = _joint_frame(exo_alone, exo_data, shoulder)
        e_elbow, e_axis = _joint_frame(exo_alone, exo_data, elbow)
        if np.linalg.norm(e_elbow - e_shoulder) < 1e-6:
            raise ConfigError("strapping.elbow_joint", f"{elbow!r} sits on {shoulder!r}: no "
                              "upper arm to strap")
        fit = _basis(p_elbow - p_shoulder, elbow_axis) @ \
            _basis(e_elbow - e_shoulder, e_axis).T
        """The exoskeleton's base orientation that puts its upper arm on the humerus."""
        turn = fit @ _euler_xyz(np.asarray(config["strapping.misalignment.rotation"],
                                           dtype=float)) @ fit.T
        offset = fit @ (np.asarray(config["strapping.misalignment.offset"], dtype=float)
                        * 1e-3)
        base_rotation = turn @ fit
        base_position = p_shoulder + offset - base_rotation @ e_shoulder
        self.base_position = base_position
        """Where the exoskeleton's base frame (its URDF's root link) sits in MuJoCo's world,
        the person's (m), misalignment included."""
        self.base_rotation = base_rotation
        """Its orientation there (rotation matrix, base axes in world)."""
        self.elbow_offset = float(np.linalg.norm(
            base_position + base_rotation @ e_elbow - p_elbow))
        """Distance (m) of the exoskeleton's elbow anchor from the person's elbow centre at
        the rest pose (link length against the humerus, and the misalignment)."""
        self.base_gravity = base_rotation.T @ np.array(alone.opt.gravity)
        """The world's gravity in the exoskeleton's base frame (m/s^2): what its nominal
        model's ``model.gravity_direction`` should say."""
        frame = person.worldbody.add_frame(pos=base_position, quat=_quat(base_rotation))
        self._cuff_bodies = [(EXO_PREFIX + self._joint_body(exo, shoulder),
                              self.anatomy.upper_arm),
                             (EXO_PREFIX + self._joint_body(exo, elbow), self.anatomy.forearm)]
        exo.option.integrator = person.option.integrator  # the person's options rule (the
        exo.option.gravity = person.option.gravity  # same values: no notice of a conflict)
        exo.option.timestep = person.option.timestep
        exo.option.disableflags = person.option.disableflags
        person.attach(exo, prefix=EXO_PREFIX, frame=frame)
        # the cuffs: a site on the exoskeleton's link, one on the bone, coincident at rest
        humerus_dir = (p_elbow - p_shoulder) / np.linalg.norm(p_elbow - p_shoulder)
        forearm_dir = (forearm_com - p_elbow) / np.linalg.norm(forearm_com - p_elbow)
        cuff_points = [p_shoulder + float(config["strapping.upper_arm_cuff"]) * humerus_dir,
                       p_elbow + float(config["strapping.forearm_cuff"]) * forearm_dir]
        # the bodies' poses at rest: the person's from its own model at the rest pose, the
        # exoskeleton's from its own at the start pose, carried by the base frame
        poses = {}
        for exo_body, bone in self._cuff_bodies:
            b = exo_alone.body(exo_body[len(EXO_PREFIX):]).id
            poses[exo_body] = (base_position + base_rotation @ exo_data.xpos[b],
                               base_rotation @ np.array(exo_data.xmat[b]).reshape(3, 3))
            b = alone.body(bone).id
            poses[bone] = (np.array(alone_data.xpos[b]),
                           np.array(alone_data.xmat[b]).reshape(3, 3))
        for cuff, point, bodies in zip(CUFFS, cuff_points, self._cuff_bodies, strict=True):
            for who, body in zip(("exo", "person"), bodies, strict=True):
                position, r_body = poses[body]
                local = r_body.T @ (point - position)
                local_rotation = r_body.T @ base_rotation  # the cuff frame: the exo's base axes
                person.body(body).add_site(name=f"cuff_{cuff}_{who}", pos=local,
                                           quat=_quat(local_rotation))
        self.model: Any = compile_quietly(person)
        self.data: Any = mujoco.MjData(self.model)
        m = self.model
        qpos_at = [int(m.jnt_qposadr[m.joint(EXO_PREFIX + j).id]) for j in self.joint_names]
        dof_at = [int(m.jnt_dofadr[m.joint(EXO_PREFIX + j).id]) for j in self.joint_names]
        if qpos_at != list(range(qpos_at[0], qpos_at[0] + n)) or \
                dof_at != list(range(dof_at[0], dof_at[0] + n)):
            raise ModelError("the exoskeleton's joints are not together at the end of the "
                             "strapped model's state")
        self._exo_qpos = slice(qpos_at[0], qpos_at[0] + n)
        self._exo_dof = slice(dof_at[0], dof_at[0] + n)
        self._qpos = self.data.qpos
        self._qvel = self.data.qvel
        self._nan = np.full(n, np.nan)
        self._warnings = self.data.warning
        self._bad_qacc = int(mujoco.mjtWarning.mjWARN_BADQACC)
        self._diverged = False
        self._bad_seen = 0
        self._exo_ctrl = np.array([m.actuator(EXO_PREFIX + j).id for j in self.joint_names])
        self.muscles = muscle_names(m)
        self._muscle_ctrl = np.array([m.actuator(a).id for a in self.muscles], dtype=int)
        self._controls = np.zeros(len(self.muscles))
        d = self.data
        self._views = (d.site_xpos, d.site_xmat, d.cvel, d.subtree_com, d.xipos)
        """MuJoCo's arrays the cuff kernel reads (views on the MjData, taken once)."""
        self._xfrc = d.xfrc_applied
        rows = []
        for c, (exo_body, bone) in zip(CUFFS, self._cuff_bodies, strict=True):
            be, bp = m.body(exo_body).id, m.body(bone).id
            rows.append([m.site(f"cuff_{c}_exo").id, m.site(f"cuff_{c}_person").id, be, bp,
                         m.body_rootid[be], m.body_rootid[bp]])
        self._bodies = np.array(rows, dtype=np.int64)
        law = self.law
        self._gains = np.array([[law.stiffness, law.damping, law.rotational_stiffness,
                                 law.rotational_damping]] * len(CUFFS), dtype=float)
        self.wrench = np.zeros((len(CUFFS), 6))
        """Force (N) and torque (N m) each cuff applies to the person at the state of the
        last :meth:`measure` (or step), in the cuff's frame."""
        self._fresh = False
        self._person_views: tuple[np.ndarray, np.ndarray] | None = None
        self.applied = np.zeros(n)
        self._no_count = np.zeros(n, dtype=np.int64)
        if drive is not None:
            self.drive = drive(config, self.model)
        self._settle(rest, np.asarray(start, dtype=float),
                     float(config["musculoskeletal.settle_time"]))
        self.trial: int | None = None
        self.index = 0

    @staticmethod
    def _joint_body(exo: Any, joint: str) -> str:
        for body in exo.bodies:
            if any(j.name == joint for j in body.joints):
                return str(body.name)
        raise ModelError(f"no body holds joint {joint!r}")

    def _full_qpos(self, model: Any, person_qpos: np.ndarray, exo_q: np.ndarray) -> np.ndarray:
        qpos = np.array(model.qpos0)
        qpos[:person_qpos.shape[0]] = person_qpos  # the person's joints come first
        for j, joint in enumerate(self.joint_names):
            qpos[model.jnt_qposadr[model.joint(EXO_PREFIX + joint).id]] = exo_q[j]
        return qpos

    def _settle(self, rest: np.ndarray, start: np.ndarray, duration: float) -> None:
        """Hold the exoskeleton at ``start`` while the person settles in the cuffs; keep the
        state every trial starts from."""
        mujoco = self._mujoco
        data = self.data
        data.qpos[:] = self._full_qpos(self.model, rest, start)
        data.qvel[:] = 0.0
        if self.drive is not None:
            mujoco.mj_forward(self.model, data)
            self.drive.reset(self.model, data)
        steps = int(round(duration / self.model.opt.timestep))
        for _ in range(steps):
            data.qpos[self._exo_qpos] = start
            data.qvel[self._exo_dof] = 0.0
            self._substep()
        data.qpos[self._exo_qpos] = start
        data.qvel[self._exo_dof] = 0.0
        data.time = 0.0
        mujoco.mj_forward(self.model, data)
        self._spec_state = mujoco.mjtState.mjSTATE_INTEGRATION
        self._start = np.zeros(mujoco.mj_stateSize(self.model, self._spec_state))
        mujoco.mj_getState(self.model, data, self._start, self._spec_state)
        self.reset()

    def reset(self) -> None:
        """The state every trial starts from (module docstring), no effort applied, the
        muscles' drive reset."""
        self._mujoco.mj_setState(self.model, self.data, self._start, self._spec_state)
        self.data.ctrl[:] = 0.0
        self.applied[:] = 0.0
        self._fresh = False
        self.trial = None
        self.index = 0
        self.diverged = False
        if self.drive is not None:  # the neural drive's memory (a reflex's delays) cleared
            self.drive.reset(self.model, self.data)

    def begin_trial(self, trial: int) -> None:
        """Trial ``trial`` starts from the kept start state (:meth:`reset`)."""
        self.reset()
        self.trial = int(trial)

    def set_state(self, q: np.ndarray, qd: np.ndarray) -> None:
        """The kept start state (a free-running plant node starts there): ``q``, ``qd`` must
        be the exoskeleton's x_d(0) it was kept at (ModelError otherwise)."""
        self.reset()
        if not (np.allclose(q, self.position, atol=1e-12) and
                np.allclose(qd, self.velocity, atol=1e-12)):
            raise ModelError("the strapped model starts only from the state it settled in "
                             "(the exoskeleton at x_d(0), at rest)")

    @property
    def position(self) -> np.ndarray:
        """The exoskeleton's q (a copy): what the controller and the law see."""
        return self._nan.copy() if self._diverged else self._qpos[self._exo_qpos].copy()

    @property
    def velocity(self) -> np.ndarray:
        """The exoskeleton's qdot (a copy)."""
        return self._nan.copy() if self._diverged else self._qvel[self._exo_dof].copy()

    def measure(self) -> tuple[np.ndarray, np.ndarray]:
        """The exoskeleton's (q, qdot) at the current sample; the cuffs' :attr:`wrench` there."""
        self._prepare()
        return self.position, self.velocity

    def _prepare(self) -> None:
        """``mj_step1`` at the current state, the cuff forces and muscle controls from it."""
        if self._fresh:
            return
        self._mujoco.mj_step1(self.model, self.data)
        self._cuff_forces()
        if self.drive is not None:
            self.drive(self.model, self.data, self._controls)
            self.data.ctrl[self._muscle_ctrl] = self._controls
        self._fresh = True

    def _substep(self) -> None:
        self._prepare()
        self._mujoco.mj_step2(self.model, self.data)
        self._fresh = False
        if self._warnings[self._bad_qacc].number != self._bad_seen:
            self.diverged = True  # MuJoCo reset its state (it does so on a bad acceleration)

    @property
    def diverged(self) -> bool:
        """True once MuJoCo found the state unstable in this trial (it then resets the state
        to the model's reference pose; the exoskeleton's state reads NaN from there, as a
        diverged plant, until :meth:`reset`)."""
        return self._diverged

    @diverged.setter
    def diverged(self, value: bool) -> None:
        self._diverged = value
        self._bad_seen = self._warnings[self._bad_qacc].number

    def _cuff_forces(self) -> None:
        """The cuffs' spring-damper forces at the fresh kinematics, into ``xfrc_applied``
        (:func:`cuff_forces_into`) and :attr:`wrench`."""
        cuff_forces_into(*self._views, self._bodies, self._gains, self._xfrc, self.wrench)

    def step(self, effort: np.ndarray, saturated: np.ndarray | None = None) -> int:
        """Hold ``effort`` (clamped to +-effort_limit) over one control period. Returns how
        many joints were beyond the limit, or -1, without stepping, for an effort that is not
        one finite value per joint."""
        if effort.shape != self.applied.shape:
            return -1
        beyond = int(clamp_counted(effort, self.limit, self._no_count if saturated is None
                                   else saturated, self.applied))
        if beyond < 0:
            return -1
        self.data.ctrl[self._exo_ctrl] = self.applied
        for _ in range(self.substeps):
            self._substep()
        self.index += 1
        return beyond

    def person_qpos(self) -> np.ndarray:
        """The person's joint angles (rad, the model's person joints, a copy)."""
        return np.array(self.data.qpos[:self.model.nq - len(self.joint_names)])

    def person_state_into(self, position: np.ndarray, velocity: np.ndarray) -> None:
        """The person's joint angles and velocities (as :meth:`person_qpos`,
        :meth:`person_qvel`) into ``position``, ``velocity``, without allocating (per
        sample)."""
        if self._person_views is None:
            n = len(self.joint_names)
            self._person_views = (self.data.qpos[:self.model.nq - n],
                                  self.data.qvel[:self.model.nv - n])
        position[:] = self._person_views[0]
        velocity[:] = self._person_views[1]

    def person_qvel(self) -> np.ndarray:
        """The person's joint velocities (rad/s, as :meth:`person_qpos`, a copy)."""
        return np.array(self.data.qvel[:self.model.nv - len(self.joint_names)])

    def person_joint_names(self) -> list[str]:
        """The person's joints in the order of :meth:`person_qpos`."""
        return person_joint_names(self.model, EXO_PREFIX)

    def person_description(self, root_link: str) -> str:
        """The person's display URDF (:func:`.display.person_urdf`), hung from the
        exoskeleton's ``root_link`` where this model places it."""
        return person_urdf(self.model, root_link, self.base_position, self.base_rotation,
                           EXO_PREFIX)


@njit(cache=True, error_model="numpy")
def rotation_vector_into(r: np.ndarray, out: np.ndarray) -> None:
    """The axis-angle vector theta (|theta| <= pi) of the rotation matrix ``r`` into ``out``."""
    cos = 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0)
    cos = min(1.0, max(-1.0, cos))
    out[0] = 0.5 * (r[2, 1] - r[1, 2])
    out[1] = 0.5 * (r[0, 2] - r[2, 0])
    out[2] = 0.5 * (r[1, 0] - r[0, 1])
    angle = np.arccos(cos)
    sin = np.sin(angle)
    if sin > 1e-9:
        for k in range(3):
            out[k] *= angle / sin


@njit(cache=True, error_model="numpy")
def point_velocity_into(cvel: np.ndarray, point: np.ndarray, centre: np.ndarray,
                        out: np.ndarray) -> None:
    """The world velocity of ``point`` of a body whose com-based velocity (MuJoCo's ``cvel``:
    angular, linear at ``centre``, the subtree centre of mass of its root) is ``cvel``:
    v = v_centre + omega x (point - centre)."""
    d0 = point[0] - centre[0]
    d1 = point[1] - centre[1]
    d2 = point[2] - centre[2]
    out[0] = cvel[3] + cvel[1] * d2 - cvel[2] * d1
    out[1] = cvel[4] + cvel[2] * d0 - cvel[0] * d2
    out[2] = cvel[5] + cvel[0] * d1 - cvel[1] * d0


@njit(cache=True, error_model="numpy")
def cuff_forces_into(site_xpos: np.ndarray, site_xmat: np.ndarray, cvel: np.ndarray,
                     subtree_com: np.ndarray, xipos: np.ndarray, bodies: np.ndarray,
                     gains: np.ndarray, xfrc: np.ndarray, wrench: np.ndarray) -> None:
    """Each cuff's spring-damper (module docstring) from MuJoCo's fresh kinematics.

    ``site_xpos`` ... ``xipos``: the MjData's arrays; ``bodies[c]``
    = (exo site, person site, exo body, person body, exo root body, person root body);
    ``gains[c]`` = (K, B, K_r, B_r) per cuff axis. A point p of body b moves at
    v = cvel_lin + omega x (p - subtree_com[root]) (MuJoCo's com-based velocity). The force on
    the exoskeleton, -K x - B v, and torque K_r theta - B_r omega (x, v, theta, omega the
    exoskeleton's displacement, velocity, rotation, angular velocity relative to the person,
    in the cuff frame = the exoskeleton site's), go into ``xfrc_applied`` of its body (at the
    body's centre of mass, as MuJoCo takes them) and the opposite into the person's;
    ``wrench[c]`` = what the person feels (force, torque; cuff frame).
    """
    xfrc[:] = 0.0
    rel = np.empty(3)
    vel = np.empty(3)
    omega = np.empty(3)
    theta = np.empty(3)
    local = np.empty(3)
    f_world = np.empty(3)
    t_world = np.empty(3)
    r_rel = np.empty((3, 3))
    for c in range(bodies.shape[0]):
        se, sp, be, bp, re, rp = bodies[c]
        re_m = site_xmat[se].reshape((3, 3))
        rp_m = site_xmat[sp].reshape((3, 3))
        for k in range(3):
            rel[k] = site_xpos[se, k] - site_xpos[sp, k]
        # velocities of the two site points, and the relative angular velocity (world)
        for k in range(3):
            omega[k] = cvel[be, k] - cvel[bp, k]
        point_velocity_into(cvel[be], site_xpos[se], subtree_com[re], vel)
        point_velocity_into(cvel[bp], site_xpos[sp], subtree_com[rp], local)
        for k in range(3):
            vel[k] -= local[k]
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += re_m[k, i] * rp_m[k, j]
                r_rel[i, j] = acc
        rotation_vector_into(r_rel, theta)
        for i in range(3):  # force and torque on the exoskeleton, cuff frame
            x = 0.0
            v = 0.0
            w = 0.0
            for k in range(3):
                x += re_m[k, i] * rel[k]
                v += re_m[k, i] * vel[k]
                w += re_m[k, i] * omega[k]
            local[i] = -gains[c, 0, i] * x - gains[c, 1, i] * v
            wrench[c, 3 + i] = gains[c, 2, i] * theta[i] - gains[c, 3, i] * w
            wrench[c, i] = local[i]
        for i in range(3):
            f_world[i] = 0.0
            t_world[i] = 0.0
            for k in range(3):
                f_world[i] += re_m[i, k] * wrench[c, k]
                t_world[i] += re_m[i, k] * wrench[c, 3 + k]
        for body, sign, site in ((be, 1.0, se), (bp, -1.0, sp)):
            arm = site_xpos[site] - xipos[body]
            xfrc[body, 0] += sign * f_world[0]
            xfrc[body, 1] += sign * f_world[1]
            xfrc[body, 2] += sign * f_world[2]
            xfrc[body, 3] += sign * (t_world[0] + arm[1] * f_world[2] - arm[2] * f_world[1])
            xfrc[body, 4] += sign * (t_world[1] + arm[2] * f_world[0] - arm[0] * f_world[2])
            xfrc[body, 5] += sign * (t_world[2] + arm[0] * f_world[1] - arm[1] * f_world[0])
        for k in range(6):
            wrench[c, k] = -wrench[c, k]
