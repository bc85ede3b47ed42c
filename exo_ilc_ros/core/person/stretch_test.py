"""The stretch test: ramp-and-hold extension of the person's elbow, without the exoskeleton, as
McPherson et al. 2018 stretched the paretic elbow (15-150 deg/s over the range of motion, arm
supported in the horizontal plane), measuring what resists it.

The elbow is driven kinematically: every step the joint's angle, velocity and acceleration are
prescribed (the other joints held at their pose, gravity off as on the horizontal support), the
neural drive (:class:`.neural_drive.NeuralDrive`) writes the muscles' excitations, MuJoCo's
muscle activation is integrated, and the torque the stretching device must apply is the
inverse dynamics of the elbow's degree of freedom,

    tau_device = (M qddot)_e + bias_e - passive_e - actuator_e,

the resistance torque its negative sign-flipped to extension (positive: resisting the
extension). Each stretch is run twice, with the person's drive and with the same drive without
its reflex: the difference is the **reflex torque** (McPherson et al. "after accounting for the
effects of passive mechanical resistance"; here exactly, inertia and passive muscle force
cancel). A hinge tau_r = K max(0, x - x_th) fitted to the reflex torque against the extension
x over the ramp, up to the reflex torque's peak, gives the **reflex stiffness** K (the
torque-angle slope, N m/rad) and the **reflex threshold angle** x_th (reported as the elbow's
flexion angle there, deg).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .model import ANATOMY, person_spec
from .neural_drive import DriveSettings, NeuralDrive, reflex_excitation, with_preset

ELBOW_FLEXORS = ("BIClong", "BICshort", "BRA", "BRD")
"""The elbow flexors: the muscles the presets make spastic (those of them the model has)."""
VELOCITIES_DEG = (15.0, 30.0, 60.0, 90.0, 120.0, 150.0)
"""McPherson et al. 2018's range of stretch velocities (deg/s)."""
REFLEX_FLOOR = 0.05
"""N m: a peak reflex torque below it is no reflex (no stiffness, no threshold angle)."""


@dataclass(frozen=True, eq=False)
class StretchPerson:
    """A musculoskeletal model ready for the stretch test: gravity off, the elbow's joint, the
    pose every other joint is held at."""

    model: object
    joint: str
    pose: np.ndarray
    name: str = ""

    @property
    def dof(self) -> int:
        return int(self.model.joint(self.joint).dofadr[0])  # type: ignore[attr-defined]

    @property
    def qpos_address(self) -> int:
        return int(self.model.joint(self.joint).qposadr[0])  # type: ignore[attr-defined]


def stretch_person(name: str = "myoelbow") -> StretchPerson:
    """Person model ``name`` (:data:`.model.PERSON_MODELS`: ``myoelbow``, MyoSuite's small
    elbow; ``myoarm``, MyoArm's pruned right arm), gravity off (the arm supported in the
    horizontal plane), every joint but the elbow held at the model's rest pose."""
    with warnings.catch_warnings():  # myo_sim's notice on an empty attach prefix
        warnings.simplefilter("ignore", UserWarning)
        model = person_spec(name).compile()
    model.opt.gravity[:] = 0.0
    anatomy = ANATOMY[name]
    pose = model.qpos0.copy()
    for joint, angle in anatomy.rest:
        pose[int(model.joint(joint).qposadr[0])] = angle
    return StretchPerson(model, anatomy.elbow_flexion, pose, name)


@dataclass(frozen=True)
class RampAndHold:
    """One ramp-and-hold extension: rest at ``start`` (flexion, rad), extend to ``end`` at
    ``velocity`` (rad/s; reached and left with a constant acceleration over ``blend`` s), hold."""

    start: float = math.radians(120.0)
    end: float = math.radians(20.0)
    velocity: float = math.radians(60.0)
    rest: float = 0.3
    hold: float = 0.5
    blend: float = 0.02

    def profile(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Time, angle, velocity and acceleration at every step (the flexion angle falls)."""
        span = self.start - self.end
        ramp = span / self.velocity + self.blend  # trapezoid: area = span
        total = self.rest + ramp + self.hold
        t = np.arange(int(math.ceil(total / dt)) + 1) * dt
        s = t - self.rest
        acc = self.velocity / self.blend
        speed = np.clip(np.minimum(s, ramp - s) * acc, 0.0, self.velocity)
        speed[(s <= 0.0) | (s >= ramp)] = 0.0
        accel = np.where((s > 0.0) & (s < self.blend), acc,
                         np.where((s > ramp - self.blend) & (s < ramp), -acc, 0.0))
        moved = np.concatenate(([0.0], np.cumsum((speed[1:] + speed[:-1]) * 0.5 * dt)))
        moved = np.minimum(moved, span)
        return t, self.start - moved, -speed, -accel

    def ramp_window(self) -> tuple[float, float]:
        """The constant-velocity part of the ramp (s from the start of the profile)."""
        return self.rest + self.blend, self.rest + (self.start - self.end) / self.velocity


@dataclass(frozen=True, eq=False)
class StretchTrace:
    """One stretch, per step."""

    time: np.ndarray
    angle: np.ndarray
    resistance: np.ndarray
    """N m resisting the extension (positive: the device pushes the forearm into extension)."""
    reflex: np.ndarray
    """(steps, muscles): the reflex excitation the drive wrote."""
    undelayed: np.ndarray
    """(steps,): the reflex law of the spastic muscles' present (not delayed) length and
    velocity, summed: what the reflex will be one delay later."""


def run_stretch(person: StretchPerson, settings: DriveSettings,
                ramp: RampAndHold) -> StretchTrace:
    """Stretch the person's elbow along ``ramp`` with ``settings``' neural drive (see the module
    docstring): resistance torque and the drive's reflex at every step."""
    import mujoco
    model = person.model
    data = mujoco.MjData(model)
    dt = float(model.opt.timestep)  # type: ignore[attr-defined]
    t, q, qd, qdd = ramp.profile(dt)
    drive = NeuralDrive(model, settings)
    spastic = drive.spastic
    e, a = person.dof, person.qpos_address
    data.qpos[:] = person.pose
    data.act[:] = settings.tone  # at rest with the tone's activation
    resistance = np.empty(t.size)
    reflex = np.zeros((t.size, drive.geometry.names.__len__()))
    undelayed = np.zeros(t.size)
    qacc = np.zeros(model.nv)  # type: ignore[attr-defined]
    inertial = np.zeros(model.nv)  # type: ignore[attr-defined]
    s = settings
    for i in range(t.size):
        data.qpos[a] = q[i]
        data.qvel[:] = 0.0
        data.qvel[e] = qd[i]
        mujoco.mj_forward(model, data)
        drive.step(data)
        length, velocity = drive.sense(data)
        undelayed[i] = float(np.sum(reflex_excitation(length, velocity, s)[spastic]))
        reflex[i] = drive.reflex
        mujoco.mj_fwdActuation(model, data)  # act_dot of the new excitation
        qacc[e] = qdd[i]
        mujoco.mj_mulM(model, data, inertial, qacc)
        device = (inertial[e] + data.qfrc_bias[e] - data.qfrc_passive[e]
                  - data.qfrc_actuator[e])
        resistance[i] = device  # extension lowers the angle: a resisting device pushes < 0
        data.act[:] = np.clip(data.act + dt * data.act_dot, 0.0, 1.0)
    return StretchTrace(t, q, -resistance, reflex, undelayed)


def hinge_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares y ~ K max(0, x - x_th) over thresholds at the samples: (x_th, K)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    candidates = x[:: max(1, x.size // 400)]
    best = (math.inf, float(x[0]), 0.0)
    for threshold in candidates:
        z = np.maximum(x - threshold, 0.0)
        zz = float(z @ z)
        if zz == 0.0:
            continue
        k = float(z @ y) / zz
        error = float(np.sum((y - k * z) ** 2))
        if error < best[0]:
            best = (error, float(threshold), k)
    return best[1], best[2]


@dataclass(frozen=True)
class StretchMeasure:
    """What one stretch of one person measured (McPherson et al. 2018's quantities)."""

    grade: str
    velocity: float
    """Stretch velocity (deg/s)."""
    resistance: float
    """Peak resistance torque over the ramp's constant velocity (N m): passive and reflex."""
    reflex_peak: float
    """Peak reflex torque over the ramp (N m)."""
    stiffness: float
    """Reflex stiffness: the torque-angle slope of the reflex torque (N m/rad); 0: no reflex."""
    threshold_angle: float | None
    """Reflex threshold angle: the elbow's flexion angle (deg) where the reflex torque starts
    (the hinge's knee); None: no reflex."""
    crossing_time: float | None
    """s after the ramp's start when the reflex law of the spastic muscles' present length and
    velocity first rose above its value at the start (a threshold crossed)."""
    onset_time: float | None
    """s after the ramp's start when the reflex torque first rose above its value at the start
    by 1 % of its rise to the peak."""

    def as_dict(self) -> dict[str, object]:
        return dict(self.__dict__)


def measure_stretch(person: StretchPerson, settings: DriveSettings, ramp: RampAndHold,
                    grade: str = "custom") -> StretchMeasure:
    """Stretch with and without the reflex and measure (module docstring)."""
    full = run_stretch(person, settings, ramp)
    passive = run_stretch(person, replace(settings, length_gain=0.0, velocity_gain=0.0), ramp)
    return measure_traces(full, passive, ramp, grade)


def measure_traces(full: StretchTrace, passive: StretchTrace, ramp: RampAndHold,
                   grade: str = "custom") -> StretchMeasure:
    """The measures of one stretch from its run with the drive (``full``) and without the
    reflex (``passive``)."""
    reflex = full.resistance - passive.resistance
    first, last = ramp.ramp_window()
    during = (full.time >= ramp.rest) & (full.time <= last)
    steady = (full.time >= first) & (full.time <= last)
    peak = float(np.max(reflex[during]))
    extension = ramp.start - full.angle
    start = ramp.rest
    begin = int(np.searchsorted(full.time, start))
    crossing = _first_time(full.time, (full.undelayed > full.undelayed[begin] + 1e-9)
                           & (full.time >= start))
    if peak < REFLEX_FLOOR:
        return StretchMeasure(grade, round(math.degrees(ramp.velocity), 9),
                              float(np.max(full.resistance[steady])), peak, 0.0, None,
                              None if crossing is None else crossing - start, None)
    at_peak = full.time[during][int(np.argmax(reflex[during]))]
    fitted = during & (full.time >= first) & (full.time <= at_peak)
    knee, slope = hinge_fit(extension[fitted], reflex[fitted] - reflex[begin])
    rise = peak - reflex[begin]
    onset = _first_time(full.time, (reflex > reflex[begin] + 0.01 * rise) & (full.time >= start))
    return StretchMeasure(grade, round(math.degrees(ramp.velocity), 9),
                          float(np.max(full.resistance[steady])), peak, slope,
                          math.degrees(ramp.start - knee),
                          None if crossing is None else crossing - start,
                          None if onset is None else onset - start)


def _first_time(time: np.ndarray, mask: np.ndarray) -> float | None:
    hits = np.flatnonzero(mask)
    return float(time[hits[0]]) if hits.size else None


@dataclass(frozen=True)
class SpringDamper:
    """McCrea et al. 2003's linear spring-damper of the hypertonic elbow, tau = K (theta -
    theta_0) + B thetadot, fitted to the resistance torque of every stretch of one person over
    the constant-velocity part of each ramp (all velocities at once, "in position-velocity
    space"); theta the extension, reported as the flexion angle theta_0 where the spring's
    torque is 0."""

    stiffness: float
    """K (N m/rad)."""
    damping: float
    """B (N m s/rad)."""
    offset_angle: float
    """theta_0 as the elbow's flexion angle (deg)."""
    r2: float
    """Share of the torque's variance the fit explains."""


def spring_damper_fit(stretches: Sequence[tuple[StretchTrace, RampAndHold]]) -> SpringDamper:
    """Least squares tau = K x + B xdot + c over every stretch's constant-velocity window (x
    the extension from the start, xdot its rate); theta_0 = start - (-c / K)."""
    rows, torque = [], []
    for trace, ramp in stretches:
        first, last = ramp.ramp_window()
        window = (trace.time >= first) & (trace.time <= last)
        x = ramp.start - trace.angle[window]
        rows.append(np.column_stack([x, np.full(x.size, ramp.velocity), np.ones(x.size)]))
        torque.append(trace.resistance[window])
    a, y = np.vstack(rows), np.concatenate(torque)
    (k, b, c), *_ = np.linalg.lstsq(a, y, rcond=None)
    residual = y - a @ np.array([k, b, c])
    r2 = 1.0 - float(residual @ residual) / float(np.sum((y - y.mean()) ** 2))
    start = stretches[0][1].start
    offset = start - (-c / k) if k != 0.0 else math.nan
    return SpringDamper(float(k), float(b), math.degrees(offset), r2)


@dataclass(frozen=True, eq=False)
class StretchTest:
    """The stretch test's results: a measure per grade and velocity, a spring-damper per
    grade."""

    measures: list[StretchMeasure]
    spring_dampers: dict[str, SpringDamper]


def stretch_test(person: StretchPerson, base: DriveSettings, grades: Sequence[str],
                 velocities_deg: Sequence[float] = VELOCITIES_DEG,
                 ramp: RampAndHold | None = None) -> StretchTest:
    """The stretch test per MAS preset and velocity: each grade's preset (tone, thresholds,
    gains, ceiling) with ``base``'s delay, spastic muscles, voluntary and fatigue settings
    (``custom``: ``base`` itself); per grade McCrea et al. 2003's spring-damper over its
    stretches."""
    ramp = ramp or RampAndHold()
    measures, fits = [], {}
    for grade in grades:
        settings = base if grade == "custom" else with_preset(base, grade)
        quiet = replace(settings, length_gain=0.0, velocity_gain=0.0)
        stretches = []
        for velocity in velocities_deg:
            this = replace(ramp, velocity=math.radians(velocity))
            full = run_stretch(person, settings, this)
            measures.append(measure_traces(full, run_stretch(person, quiet, this), this, grade))
            stretches.append((full, this))
        fits[grade] = spring_damper_fit(stretches)
    return StretchTest(measures, fits)
