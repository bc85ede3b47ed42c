"""The virtual patient: what a real arm in the exoskeleton adds to the paper's plant, eq (6)
(which keeps the viscous, spring and friction forces Q^v, Q^c, Q^f and sets them to zero).

Every effect is a ``patient.*`` parameter of the plant_simulator section, off by default (the
shipped config gives the paper's numbers bit for bit). Its per-joint values are for the
patient's joints: the arm's, or those ``patient.joints`` names, each acting on the arm joint it
maps to (:func:`patient_values`; an arm joint not named gets no patient effect). One code path:
the compiled trial of :func:`trial.simulate_trial_guarded` and the plant_simulator node's
:class:`plant.PlantStepper` call the same kernels below in the same order, so the graph equals
the in-process runner.

Per sample i of a trial (true state x_i = (q_i, qdot_i) of the plant):

1. **Sensors** (:func:`measure_into`): the controller and the learning law see the measured
   q^m_i = Q(q_i) + n^q_i, Q the encoder quantisation (round to the resolution), n^q Gaussian;
   qdot^m_i = qdot_i + n^v_i, or, with ``differentiate_velocity``, (q^m_i - q^m_{i-1}) / T + n^v_i
   (0 at i = 0), optionally low-passed, v_i = v_{i-1} + a (raw_i - v_{i-1}), a = T / (tau + T).
2. **Held torques** over [t_i, t_i+1) (:func:`patient_period`): the actuator applies the command
   of sample i - d (``effort_delay`` d control periods; the first command before that); the
   **stretch reflex** adds -sgn(v) min(G max(0, |v| - v_th), R) with v = qdot at sample
   i - d_r (``reflex_delay`` rounded to control periods) and R the reflex's ceiling
   ``reflex_max`` (a muscle's force saturates; 0: no ceiling); the **voluntary effort** adds
   tau^v_i = tau^v_{i-1} + a_v (g_k (K_v (q_d(t_i + s_k) - q_i) + D_v (qdot_d(t_i + s_k) - qdot_i))
   - tau^v_{i-1}): the patient's own sluggish tracking (first-order lag a_v = T / (tau_v + T)) of
   the reference shifted by the trial's timing jitter s_k, with gain g_k = (1 + sigma_a z_k)
   (amplitude jitter, >= 0) times the fatigue f_k = f_min + (1 - f_min) exp(-r (k - 1)); a
   **learning patient** adds the torque profile x_f + x_s of :class:`PatientLearning`.
3. **Passive joint forces** at every RK4 stage (:func:`joint_forces.passive_effort_into`,
   in :func:`plant.rk4_period_with_joint_forces`): -B qdot
   - F_c tanh(qdot / v_s) - K (q - q_0), with B = viscous friction + spastic damping and K =
   passive + spastic stiffness. A URDF arm's own ``<dynamics damping friction>``
   (``model.urdf_joint_dynamics: apply``, :func:`..arm.build.urdf_joint_dynamics`) is added to
   B and F_c: the arm's joint forces and the patient's share this one integrator and v_s.

Each trial k starts at x_d(0) plus a Gaussian offset. All randomness of trial k (noise per
sample, the initial offset, the jitters) is drawn before the trial from
``default_rng(SeedSequence([patient.seed, k]))``, or, in the patient's therapy session s >= 2
(``patient.session``), from ``SeedSequence([patient.seed, s, k])`` (:meth:`PatientModel.draws`),
so a resumed run, a rerun of trial k and the graph's plant draw the same numbers while each
session draws its own; fatigue is a function of k.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.build import urdf_joint_dynamics
from ..arm.joint_forces import COULOMB, REST, STIFFNESS, VISCOUS
from ..params import schema
from ..params.config import Config
from .plant import PlantIntegration, clamp_counted, rk4_period_with_joint_forces
from .record import TrialRecord

# Rows of the per-joint parameter array ``joint`` (kernel argument); rows 0-3 (VISCOUS B,
# COULOMB F_c, STIFFNESS K, REST q_0) are the passive forces' (:mod:`.joint_forces`):
REFLEX_GAIN = 4  # G (N m s/rad)
REFLEX_THRESHOLD = 5  # v_th (rad/s)
VOLUNTARY_STIFFNESS = 6  # K_v (N m/rad)
VOLUNTARY_DAMPING = 7  # D_v (N m s/rad)
REFLEX_MAX = 8  # the reflex torque's ceiling (N m); 0: none
_JOINT_ROWS = 9

# Entries of the scalar array ``scalars`` (kernel argument):
QUANTISATION = 0  # rad, 0: none
DIFFERENTIATE = 1  # 1.0: velocity from differentiated measured position
INVERSE_STRIBECK = 2  # 1 / v_s (s/rad)
REFLEX_DELAY = 3  # control periods
VOLUNTARY_ALPHA = 4  # a_v = T / (tau_v + T)
EFFORT_DELAY = 5  # control periods
PASSIVE_ON = 6  # 1.0: passive forces in the RK4 stages
HELD_ON = 7  # 1.0: reflex or voluntary torque
SENSOR_ON = 8  # 1.0: the measured state differs from the true one
VELOCITY_ALPHA = 9  # a = T / (tau + T) of the velocity filter (1: none)
PERIOD = 10  # T (s)
LEARNING_ON = 11  # 1.0: the patient's learned torque profile is added
_SCALARS = 12

MAS_PRESETS: dict[str, tuple[float, float, float, float, float]] = {
    "0": (0.0, 0.0, 0.0, 0.0, 0.0),
    "1": (1.0, 0.1, 0.25, 0.5, 0.66),
    "1+": (2.0, 0.2, 0.5, 0.35, 1.4),
    "2": (4.0, 0.4, 1.0, 0.2, 2.9),
    "3": (8.0, 0.8, 2.0, 0.1, 6.1),
}
"""MAS grade -> (stiffness N m/rad, damping N m s/rad, reflex gain N m s/rad, reflex threshold
rad/s, reflex ceiling N m), the same on every joint. Derived, not fitted: McCrea et al. 2003 (J
Neurosci Methods 128:121) found the spring-damper stiffness and damping of the hypertonic elbow
to rise with the MAS (r = 0.82); here they double from grade to grade, grade 1 adding about the
normal passive elbow stiffness (0.4-1.8 N m/rad, Wiegner and Watts 1986, JNNP 49:1171) and ten
times the OpenSim arm damping (0.1 N m s/rad, Saul et al. 2015). Reflex: the delayed
velocity-threshold reflex of SpasticMyoElbow (delay 0.1 s), its gain doubling and its threshold
falling with the grade (reflex stiffness explains ~74 % of the velocity-dependent resistance,
McPherson et al. 2018). Ceiling: the preset's own reflex at 180 deg/s (pi rad/s), G (pi - v_th)
to two digits, the fastest stretch of the data behind it (McCrea et al. 2003 stretched at 30-180
deg/s, McPherson et al. 2018 at 15-150 deg/s): the linear reflex is not extrapolated beyond the
velocities measured, and stays there above them (a judgement: a muscle's force and reflex EMG
saturate; stretch-evoked torque depends only weakly on velocity, Powers, Campbell and Rymer
1989, Ann Neurol 26:32). A fitted table for one patient should replace them."""


def patient_joint_indices(config: Config) -> np.ndarray:
    """The arm joint (index into ``joint_names``) each of the patient's joints acts on, in the
    order of the ``patient.*`` per-joint lists: ``patient.joints``, or every arm joint when it
    is empty."""
    names = config["joint_names"]
    mapping = schema.parse_patient_joints(config[schema.PATIENT_JOINTS])
    if not mapping:
        return np.arange(len(names))
    return np.array([names.index(arm) for arm, _ in mapping.values()], dtype=np.intp)


def patient_joint_signs(config: Config) -> np.ndarray:
    """+1 or -1 per patient joint: -1 where the patient's angle grows as the arm joint's
    falls (``-arm_joint`` in ``patient.joints``)."""
    mapping = schema.parse_patient_joints(config[schema.PATIENT_JOINTS])
    if not mapping:
        return np.ones(config.joints)
    return np.array([sign for _, sign in mapping.values()])


def rest_positions(config: Config) -> np.ndarray:
    """q_0 per arm joint, in the arm's angles: ``patient.joint_zero`` + sign x
    ``patient.passive.rest_position`` (0 where no patient joint acts: no stiffness there)."""
    zero = np.asarray(config["patient.joint_zero"], dtype=float)
    rest = np.asarray(config["patient.passive.rest_position"], dtype=float)
    return on_arm_joints(config, zero + patient_joint_signs(config) * rest)


def on_arm_joints(config: Config, values: Sequence[float]) -> np.ndarray:
    """A value per patient joint as one per arm joint (0 on an arm joint no patient joint
    acts on: no effect there)."""
    out = np.zeros(config.joints)
    out[patient_joint_indices(config)] = values
    return out


def patient_values(config: Config, key: str) -> np.ndarray:
    """``patient.<key>`` (a per-joint value of the patient) per arm joint
    (:func:`on_arm_joints`)."""
    return on_arm_joints(config, config[f"patient.{key}"])


def spasticity_values(config: Config) -> tuple[list[float], list[float], list[float],
                                                list[float], list[float]]:
    """Per arm joint: spastic stiffness, damping, reflex gain, reflex threshold, reflex ceiling
    (0: none) (the MAS preset on every patient joint, or the ``custom`` values; 0 on an arm
    joint the patient does not act on)."""
    grade = config["patient.spasticity.mas_grade"]
    n = len(patient_joint_indices(config))
    if grade != "custom":
        values = [[x] * n for x in MAS_PRESETS[grade]]
    else:
        values = [config[f"patient.spasticity.{key}"] for key in
                  ("stiffness", "damping", "reflex_gain", "reflex_threshold", "reflex_max")]
    k, b, g, th, ceiling = (on_arm_joints(config, v).tolist() for v in values)
    return k, b, g, th, ceiling


@dataclass(frozen=True, eq=False)
class TrialDraws:
    """Everything random about one trial, drawn before it runs (kernel arguments)."""

    noise: np.ndarray
    """(2, N+1, joints): position then velocity noise at every sample (rad, rad/s)."""
    initial: np.ndarray
    """(2, joints): offset of q(0) and qdot(0) from x_d(0)."""
    trial_scalars: np.ndarray
    """[voluntary gain g_k f_k, timing shift s_k in samples]."""


class PatientTrial(NamedTuple):
    """The virtual patient in one trial as one kernel argument (:func:`patient_period`):
    made by :func:`patient_trial`."""

    q_ref: np.ndarray
    """(N+1, n): the reference positions the voluntary effort tracks."""
    qd_ref: np.ndarray
    """(N+1, n): the reference velocities."""
    joint: np.ndarray
    """:attr:`PatientModel.joint` (per-joint parameters)."""
    scalars: np.ndarray
    """:attr:`PatientModel.scalars` (empty: the patient is off)."""
    noise: np.ndarray
    """The trial's :attr:`TrialDraws.noise`."""
    initial: np.ndarray
    """The trial's :attr:`TrialDraws.initial`."""
    trial_scalars: np.ndarray
    """The trial's :attr:`TrialDraws.trial_scalars`."""
    learned: np.ndarray
    """(N+1, n): the torque a learning patient adds (:class:`PatientLearning`)."""
    history: np.ndarray
    """(2, N+1, n) scratch: the true velocities and commands of the trial so far."""
    memory: np.ndarray
    """(3, n) zeros at the trial's start: the lagged voluntary torque, the previous measured
    position and filtered velocity."""
    held: np.ndarray
    """(n,): the torque held over the last period."""
    total: np.ndarray
    """(n,) scratch: the torque each RK4 stage integrates."""


def patient_trial(model: PatientModel, draws: TrialDraws, q_ref: np.ndarray,
                  qd_ref: np.ndarray, learned: np.ndarray) -> PatientTrial:
    """The :class:`PatientTrial` of ``model`` with a trial's ``draws``, fresh scratch arrays
    and zero memory (no history when the patient is off)."""
    samples, n = q_ref.shape
    return PatientTrial(q_ref, qd_ref, model.joint, model.scalars, draws.noise, draws.initial,
                        draws.trial_scalars, learned,
                        np.empty((2, samples if model.enabled else 0, n)), np.zeros((3, n)),
                        np.empty(n), np.empty(n))


class PatientModel:
    """The ``patient.*`` parameters of a config as kernel arguments (module docstring), with a
    URDF arm's applied joint dynamics in the passive forces' rows."""

    def __init__(self, config: Config) -> None:
        n = config.joints
        period = float(config["control.period"])
        self.seed = int(config["patient.seed"])
        self.session = int(config["patient.session"])
        """The patient's therapy session (1: the first, or none)."""
        self.period = period
        stiff, damp, gain, threshold, reflex_max = spasticity_values(config)
        joint = np.zeros((_JOINT_ROWS, n))
        arm_damping, arm_friction = urdf_joint_dynamics(config)
        joint[VISCOUS] = patient_values(config, "friction.viscous") + damp + arm_damping
        joint[COULOMB] = patient_values(config, "friction.coulomb") + arm_friction
        joint[STIFFNESS] = patient_values(config, "passive.stiffness") + stiff
        joint[REST] = rest_positions(config)
        joint[REFLEX_GAIN] = gain
        joint[REFLEX_THRESHOLD] = threshold
        joint[REFLEX_MAX] = reflex_max
        joint[VOLUNTARY_STIFFNESS] = patient_values(config, "voluntary.stiffness")
        joint[VOLUNTARY_DAMPING] = patient_values(config, "voluntary.damping")
        self.joint = joint
        arm_joint = np.zeros((_JOINT_ROWS, n))
        arm_joint[VISCOUS] = arm_damping
        arm_joint[COULOMB] = arm_friction
        self.arm_joint = arm_joint
        """The arm's own joint forces alone (a URDF arm's applied ``<dynamics>``): what the
        plant integrates between trials, where the patient is not (:class:`.stepper.
        PlantStepper`)."""
        self.arm_forces = bool(np.any(arm_joint != 0.0))
        """The arm has joint forces of its own."""
        self.inverse_stribeck = 1.0 / float(config["patient.friction.stribeck_velocity"])
        """1 / v_s of every smooth Coulomb term (s/rad)."""
        self.position_noise = float(config["patient.sensor.position_noise"])
        self.velocity_noise = float(config["patient.sensor.velocity_noise"])
        self.initial_position = float(config["patient.initial.position_sd"])
        self.initial_velocity = float(config["patient.initial.velocity_sd"])
        self.amplitude_sd = float(config["patient.voluntary.amplitude_sd"])
        self.timing_sd = float(config["patient.voluntary.timing_sd"])
        self.fatigue_rate = float(config["patient.voluntary.fatigue_rate"])
        self.fatigue_floor = float(config["patient.voluntary.fatigue_floor"])
        quantisation = float(config["patient.sensor.quantisation"])
        differentiate = bool(config["patient.sensor.differentiate_velocity"])
        velocity_filter = float(config["patient.sensor.velocity_filter"])
        voluntary_lag = float(config["patient.voluntary.time_constant"])
        reflex_delay = int(round(float(config["patient.spasticity.reflex_delay"]) / period))
        effort_delay = int(config["patient.effort_delay"])
        self.learning_gain = patient_values(config, "learning.gain")
        self.learning = (float(config["patient.learning.fast_retention"]),
                         float(config["patient.learning.fast_rate"]),
                         float(config["patient.learning.slow_retention"]),
                         float(config["patient.learning.slow_rate"]))
        self.learns = bool(np.any(self.learning_gain != 0.0))
        """The patient learns across trials (:class:`PatientLearning`)."""
        self.measures = bool(quantisation > 0.0 or differentiate or velocity_filter > 0.0
                             or self.position_noise > 0.0 or self.velocity_noise > 0.0)
        """The measured state differs from the true one (the record carries both)."""
        passive = bool(np.any(joint[[VISCOUS, COULOMB, STIFFNESS]] != 0.0))
        reflex = bool(np.any(joint[REFLEX_GAIN] != 0.0))
        voluntary = bool(np.any(joint[[VOLUNTARY_STIFFNESS, VOLUNTARY_DAMPING]] != 0.0))
        self.enabled = bool(self.measures or passive or reflex or voluntary or effort_delay
                            or self.initial_position > 0.0 or self.initial_velocity > 0.0
                            or self.learns)
        """Any effect is on (else the plant is the paper's, and the kernels skip all this)."""
        scalars = np.zeros(_SCALARS)
        scalars[QUANTISATION] = quantisation
        scalars[DIFFERENTIATE] = float(differentiate)
        scalars[INVERSE_STRIBECK] = 1.0 / float(config["patient.friction.stribeck_velocity"])
        scalars[REFLEX_DELAY] = float(reflex_delay)
        scalars[VOLUNTARY_ALPHA] = period / (voluntary_lag + period)
        scalars[EFFORT_DELAY] = float(effort_delay)
        scalars[PASSIVE_ON] = float(passive)
        scalars[HELD_ON] = float(reflex or voluntary)
        scalars[SENSOR_ON] = float(self.measures)
        scalars[VELOCITY_ALPHA] = period / (velocity_filter + period)
        scalars[PERIOD] = period
        scalars[LEARNING_ON] = float(self.learns)
        self.scalars = scalars if self.enabled else np.zeros(0)
        """Empty when no effect is on: the kernels then run the paper's plant unchanged."""

    def fatigue(self, trial: int) -> float:
        """f_k = f_min + (1 - f_min) exp(-r (k - 1)): the voluntary gain left at trial k."""
        return self.fatigue_floor + (1.0 - self.fatigue_floor) * math.exp(
            -self.fatigue_rate * (trial - 1))

    def entropy(self, trial: int) -> list[int]:
        """What trial ``trial``'s draws are seeded with: [seed, trial] in session 1 (and outside
        a therapy session: the numbers of every run before sessions existed), [seed, session,
        trial] in session 2 and later."""
        if self.session <= 1:
            return [self.seed, int(trial)]
        return [self.seed, self.session, int(trial)]

    def draws(self, trial: int, samples: int) -> TrialDraws:
        """Trial ``trial``'s random numbers from ``SeedSequence(entropy(trial))``, always drawn
        in the same order and number (turning one effect on does not change the others'):
        noise (2, samples, joints), initial offsets (2, joints), amplitude, timing."""
        n = self.joint.shape[1]
        if not self.enabled:
            return TrialDraws(np.zeros((2, 0, 0)), np.zeros((2, 0)), np.zeros(2))
        rng = np.random.default_rng(np.random.SeedSequence(self.entropy(trial)))
        noise = rng.standard_normal((2, samples, n))
        initial = rng.standard_normal((2, n))
        amplitude, timing = rng.standard_normal(2)
        noise[0] *= self.position_noise
        noise[1] *= self.velocity_noise
        initial[0] *= self.initial_position
        initial[1] *= self.initial_velocity
        gain = max(0.0, 1.0 + self.amplitude_sd * float(amplitude)) * self.fatigue(trial)
        shift = float(round(self.timing_sd * float(timing) / self.period))
        return TrialDraws(noise, initial, np.array([gain, shift]))


class PatientLearning:
    """A patient who learns across trials: the two-state model of motor adaptation (a fast and
    a slow state, Smith, Ghazizadeh and Shadmehr 2006), per sample and joint,

        x_f <- A_f x_f + B_f K_e e_k,   x_s <- A_s x_s + B_s K_e e_k,

    e_k = q_d - q the true error of trial k at every sample; the patient adds x_f + x_s (N m) to
    the next trial's torque (held over each period). The state after trial k is a function of
    the true errors of trials 1..k, which the store keeps, so a resumed run rebuilds it
    (:meth:`learn` over the restored records)."""

    def __init__(self, model: PatientModel, samples: int) -> None:
        n = model.learning_gain.shape[0]
        self.model = model
        self.fast = np.zeros((samples, n))
        self.slow = np.zeros((samples, n))
        self.torque = np.zeros((samples, n))
        """x_f + x_s: what the patient adds in the next trial."""
        self.learned_through = 0
        """The last trial learned from (0: none)."""

    def learn(self, trial: int, true_error: np.ndarray) -> None:
        """Learn from trial ``trial`` (the next after :attr:`learned_through`) with its true
        error q_d - q at every sample."""
        if trial != self.learned_through + 1:
            raise ValueError(f"the patient learns from trial {self.learned_through + 1} next, "
                             f"not {trial}")
        a_f, b_f, a_s, b_s = self.model.learning
        drive = self.model.learning_gain * true_error
        self.fast = a_f * self.fast + b_f * drive
        self.slow = a_s * self.slow + b_s * drive
        self.torque = self.fast + self.slow
        self.learned_through = trial


def true_error(record: TrialRecord) -> np.ndarray:
    """q_d - q of the plant's true state at every sample of a record."""
    true = record.position if record.true_position is None else record.true_position
    return np.asarray(record.reference.position - true)


@njit(cache=True, error_model="numpy")
def measure_into(i: int, q: np.ndarray, qd: np.ndarray, scalars: np.ndarray, noise: np.ndarray,
                 memory: np.ndarray, q_out: np.ndarray, qd_out: np.ndarray) -> None:
    """The sensors at sample ``i`` (module docstring, step 1): measured q and qdot of the true
    (q, qdot) into ``q_out``, ``qd_out``. ``memory`` rows 1 and 2 keep the previous measured
    position and filtered velocity (the trial's sensor state)."""
    resolution = scalars[QUANTISATION]
    period = scalars[PERIOD]
    alpha = scalars[VELOCITY_ALPHA]
    differentiate = scalars[DIFFERENTIATE] > 0.0
    for j in range(q.shape[0]):
        x = q[j]
        if resolution > 0.0:
            x = np.floor(x / resolution + 0.5) * resolution
        x += noise[0, i, j]
        v = qd[j]
        if differentiate:
            v = 0.0 if i == 0 else (x - memory[1, j]) / period
        v += noise[1, i, j]
        if alpha < 1.0 and i > 0:
            v = memory[2, j] + alpha * (v - memory[2, j])
        memory[1, j] = x
        memory[2, j] = v
        q_out[j] = x
        qd_out[j] = v


@njit(cache=True, error_model="numpy")
def patient_period(i: int, q: np.ndarray, qd: np.ndarray, command: np.ndarray,
                   integration: PlantIntegration, patient: PatientTrial) -> None:
    """In place: the true (q, qdot) of sample ``i`` advanced one period with the patient
    (module docstring, steps 2 and 3). ``command`` is the clamped effort of sample i; the
    ``patient``'s ``history`` keeps the true velocities and commands of the trial so far,
    ``memory`` row 0 the lagged voluntary torque, ``held`` receives the torque held over the
    period (actuator plus reflex plus voluntary plus the ``learned`` torque of a learning
    patient, :class:`PatientLearning`)."""
    n = q.shape[0]
    q_ref = patient.q_ref
    qd_ref = patient.qd_ref
    joint = patient.joint
    scalars = patient.scalars
    trial_scalars = patient.trial_scalars
    history = patient.history
    memory = patient.memory
    held = patient.held
    last = q_ref.shape[0] - 1
    for j in range(n):
        history[0, i, j] = qd[j]
        history[1, i, j] = command[j]
    delay = int(scalars[EFFORT_DELAY])
    k = i - delay if i >= delay else 0
    for j in range(n):
        held[j] = history[1, k, j]
    if scalars[HELD_ON] > 0.0:
        reflex_delay = int(scalars[REFLEX_DELAY])
        r = i - reflex_delay if i >= reflex_delay else 0
        s = i + int(trial_scalars[1])
        s = 0 if s < 0 else (last if s > last else s)
        gain = trial_scalars[0]
        alpha = scalars[VOLUNTARY_ALPHA]
        for j in range(n):
            v = history[0, r, j]
            excess = abs(v) - joint[REFLEX_THRESHOLD, j]
            if excess > 0.0:
                reflex = joint[REFLEX_GAIN, j] * excess
                ceiling = joint[REFLEX_MAX, j]
                if 0.0 < ceiling < reflex:
                    reflex = ceiling
                held[j] -= reflex * (1.0 if v > 0.0 else -1.0)
            raw = gain * (joint[VOLUNTARY_STIFFNESS, j] * (q_ref[s, j] - q[j])
                          + joint[VOLUNTARY_DAMPING, j] * (qd_ref[s, j] - qd[j]))
            memory[0, j] += alpha * (raw - memory[0, j])
            held[j] += memory[0, j]
    if scalars[LEARNING_ON] > 0.0:
        learned = patient.learned
        for j in range(n):
            held[j] += learned[i, j]
    rk4_period_with_joint_forces(q, qd, held, integration, scalars[PASSIVE_ON] > 0.0, joint,
                                 scalars[INVERSE_STRIBECK], patient.total)


@njit(cache=True, error_model="numpy")
def start_state_into(q_ref0: np.ndarray, qd_ref0: np.ndarray, initial: np.ndarray,
                     q: np.ndarray, qd: np.ndarray) -> None:
    """The trial's true start: x_d(0) plus the trial's initial offset."""
    for j in range(q.shape[0]):
        q[j] = q_ref0[j] + initial[0, j]
        qd[j] = qd_ref0[j] + initial[1, j]


@njit(cache=True, error_model="numpy")
def patient_plant_period(i: int, effort: np.ndarray, limit: np.ndarray, saturated: np.ndarray,
                         q: np.ndarray, qd: np.ndarray, applied: np.ndarray,
                         integration: PlantIntegration, patient: PatientTrial) -> int:
    """:func:`plant.plant_period` with the patient: refuse a non-finite effort (-1, nothing
    changes), count saturation, clamp into ``applied`` (:func:`plant.clamp_counted`), then
    :func:`patient_period` from sample ``i``. Returns the number of joints beyond the limit."""
    beyond = clamp_counted(effort, limit, saturated, applied)
    if beyond >= 0:
        patient_period(i, q, qd, applied, integration, patient)
    return beyond
