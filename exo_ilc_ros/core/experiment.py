"""The paper's experiment in-process: config -> nominal model, plant, reference and law; one
trial of the closed loop (:class:`Experiment`). The trial-to-trial loop is ``core.session``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .assist import with_assist
from .config import Config
from .errors import SafetyError
from .hold import ramp_samples
from .laws import (
    ErrorSum,
    InitialFeedforward,
    LearningLaw,
    LinearLaw,
    Memory,
    ScheduleIndex,
    SignLaw,
    StepSchedule,
    TrialRecord,
)
from .model import ArmModel
from .patient import PatientModel
from .plant import PlantDynamics
from .qfilter import QFilteredLaw, feedforward_limit_of, qfilter_of
from .trajectory import QuinticTrajectory, SampledReference
from .trial import simulate_trial_guarded

_NO_TORQUE = np.zeros((0, 0))


def build_arm(config: Config) -> ArmModel:
    """The nominal arm of the config (the model the computed torque uses)."""
    return ArmModel.from_links(config["model.link_masses"], config["model.link_lengths"],
                               config["model.radius_proximal"], config["model.radius_distal"],
                               config["model.joint_axes"], config["model.gravity"])


def build_reference(config: Config) -> SampledReference:
    """The quintic reference of eq (14) sampled at the control period, or the config's
    exercise (``exercise.name``, a piecewise quintic through rest points, :mod:`.exercise`)."""
    from .exercise import exercise_reference

    exercise = exercise_reference(config)
    if exercise is not None:
        return exercise
    trajectory = QuinticTrajectory.rest_to_rest(config["trajectory.start"],
                                                config["trajectory.goal"],
                                                config["trajectory.duration"])
    return SampledReference.from_trajectory(trajectory, config["control.period"])


def build_schedule(config: Config, term: str) -> StepSchedule:
    """The step function of ``term`` (position, velocity or acceleration), eqs (22)-(24)."""
    base = f"schedule.{term}."
    return StepSchedule.from_values(*(config[base + k] for k in (
        "threshold_low", "threshold_high", "level_low", "level_mid", "level_high")))


def build_law(config: Config, law: str | None = None) -> LearningLaw:
    """The learning law named by ``law`` (default: the config's ``law``) with its options,
    with assist-as-needed when the config enables it (:mod:`.assist`), wrapped in
    :class:`QFilteredLaw` when the config enables the Q-filter or a
    ``feedforward_limit``."""
    inner = with_assist(_build_plain_law(config, law), config)
    qfilter = qfilter_of(config)
    limit = feedforward_limit_of(config)
    if qfilter is None and limit is None:
        return inner
    return QFilteredLaw(inner, qfilter, limit)


def _build_plain_law(config: Config, law: str | None) -> LearningLaw:
    name = law or config["law"]
    memory = Memory(config["memory"])
    initial = InitialFeedforward(config["initial_feedforward"])
    if name == "sign":
        return SignLaw(build_schedule(config, "position"), build_schedule(config, "velocity"),
                       build_schedule(config, "acceleration"), memory,
                       ScheduleIndex(config["schedule_index"]), ErrorSum(config["error_sum"]),
                       initial)
    if name == "linear":
        return LinearLaw(np.asarray(config["linear.gain_position"]),
                         np.asarray(config["linear.gain_velocity"]),
                         np.asarray(config["linear.gain_acceleration"]), memory, initial)
    if name == "norm_optimal":
        from .norm_optimal import NormOptimalLaw

        return NormOptimalLaw.from_config(config)
    raise ValueError(f"unknown law {name!r}; use sign, linear or norm_optimal")


@dataclass(frozen=True)
class IterationsToBound:
    """Per joint: the first trial within the bound, and the trial from which it stays within
    (None where never reached, or not yet staying within at the last trial)."""

    first: list[int | None]
    settled: list[int | None]


def iterations_to_bound(max_abs_errors: np.ndarray, bound: float) -> IterationsToBound:
    """First and settled trial (1-based) per joint from the (K, joints) max |e| table."""
    within = np.asarray(max_abs_errors) <= bound
    first: list[int | None] = []
    settled: list[int | None] = []
    for j in range(within.shape[1]):
        hits = np.flatnonzero(within[:, j])
        first.append(int(hits[0]) + 1 if hits.size else None)
        misses = np.flatnonzero(~within[:, j])
        if not within[-1, j]:
            settled.append(None)
        else:
            settled.append(int(misses[-1]) + 2 if misses.size else 1)
    return IterationsToBound(first, settled)


class Experiment:
    """The closed loop of one configuration: nominal model in the controller, the plant with
    masses scaled by (1 + mass_uncertainty), the sampled reference, gains and limits."""

    def __init__(self, config: Config, mass_uncertainty: float | None = None) -> None:
        self.config = config
        self.mass_uncertainty = float(config["mass_uncertainty"] if mass_uncertainty is None
                                      else mass_uncertainty)
        self.nominal = build_arm(config)
        self.plant = self.nominal.with_mass_scale(self.mass_uncertainty)
        self.reference = build_reference(config)
        self.kp = np.asarray(config["control.kp"], dtype=float)
        self.kd = np.asarray(config["control.kd"], dtype=float)
        self.effort_limit = np.asarray(config["control.effort_limit"], dtype=float)
        self.error_envelope = np.asarray(config["safety.error_envelope"], dtype=float)
        self.hold_kp = np.asarray(config["safety.hold_kp"], dtype=float)
        self.hold_kd = np.asarray(config["safety.hold_kd"], dtype=float)
        self.hold_ramp = ramp_samples(config["safety.hold_ramp"], config["control.period"])
        """The safe hold's gains and ramp (samples) (:mod:`.hold`): every place that commands
        the hold takes them from here."""
        self.period = float(config["control.period"])
        self.substeps = int(round(self.period / config["integration_step"]))
        self.dynamics = PlantDynamics.FULL if config["dynamics"] == "full" \
            else PlantDynamics.PAPER_APPROXIMATION
        self.patient = PatientModel(config)
        """The virtual patient's effects (all off by default)."""

    def run_trial(self, feedforward: np.ndarray, trial: int,
                  levels: np.ndarray | None = None,
                  learned: np.ndarray | None = None) -> TrialRecord:
        """One trial with the given feed-forward, from x_d(0), guarded by the error envelope
        (``record.aborted_at`` set if it left it: safe hold from that sample on), with the
        virtual patient's effects and trial ``trial``'s draws (:mod:`.patient`); ``learned``:
        the torque a learning patient adds (:class:`.patient.PatientLearning`; None: none)."""
        ref = self.reference
        u_ff = np.ascontiguousarray(feedforward, dtype=float)
        if u_ff.shape != ref.position.shape:
            raise ValueError(f"feed-forward must have shape {ref.position.shape}, "
                             f"got {u_ff.shape}")
        if not np.all(np.isfinite(u_ff)):
            raise SafetyError(f"trial {trial}: the feed-forward holds non-finite values; "
                              "refusing to run it")
        patient = self.patient
        draws = patient.draws(trial, ref.samples)
        q, qd, u, effort, abort, q_true, qd_true = simulate_trial_guarded(
            u_ff, ref.position, ref.velocity, self.kp, self.kd, self.effort_limit, self.period,
            self.substeps, self.plant.kernel_args, self.nominal.kernel_args, int(self.dynamics),
            self.error_envelope, self.hold_kp, self.hold_kd, self.hold_ramp, patient.joint,
            patient.scalars, draws.noise, draws.initial, draws.trial_scalars,
            learned if learned is not None
            else np.zeros(ref.position.shape) if patient.learns else _NO_TORQUE)
        measured = patient.measures
        return TrialRecord(trial, ref, q, qd, u_ff, u, effort, levels,
                           None if abort < 0 else int(abort), q_true if measured else None,
                           qd_true if measured else None)
