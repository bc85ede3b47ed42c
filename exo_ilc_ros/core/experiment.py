"""The paper's experiment in-process: config -> models, reference and law -> K trials -> results."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .config import Config
from .errors import SafetyError, StoreError
from .integrator import PlantDynamics
from .laws import (
    ErrorSum,
    FeedforwardUpdate,
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
from .qfilter import QFilteredLaw, feedforward_limit_of, qfilter_of
from .safety import simulate_trial_guarded
from .store import RunStore
from .trajectory import QuinticTrajectory, SampledReference


def build_arm(config: Config) -> ArmModel:
    """The nominal arm of the config (the model the computed torque uses)."""
    return ArmModel.from_links(config["model.link_masses"], config["model.link_lengths"],
                               config["model.radius_proximal"], config["model.radius_distal"],
                               config["model.joint_axes"], config["model.gravity"])


def build_reference(config: Config) -> SampledReference:
    """The quintic reference of eq (14) sampled at the control period."""
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
    wrapped in :class:`QFilteredLaw` when the config enables the Q-filter or a
    ``feedforward_limit``."""
    inner = _build_plain_law(config, law)
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
    raise ValueError(f"unknown law {name!r}; use sign or linear")


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
        self.period = float(config["control.period"])
        self.substeps = int(round(self.period / config["integration_step"]))
        self.dynamics = PlantDynamics.FULL if config["dynamics"] == "full" \
            else PlantDynamics.PAPER_APPROXIMATION

    def run_trial(self, feedforward: np.ndarray, trial: int,
                  levels: np.ndarray | None = None) -> TrialRecord:
        """One trial with the given feed-forward, from x_d(0), guarded by the error envelope
        (``record.aborted_at`` set if it left it: safe hold from that sample on)."""
        ref = self.reference
        u_ff = np.ascontiguousarray(feedforward, dtype=float)
        if u_ff.shape != ref.position.shape:
            raise ValueError(f"feed-forward must have shape {ref.position.shape}, "
                             f"got {u_ff.shape}")
        if not np.all(np.isfinite(u_ff)):
            raise SafetyError(f"trial {trial}: the feed-forward holds non-finite values; "
                              "refusing to run it")
        q, qd, u, effort, abort = simulate_trial_guarded(
            u_ff, ref.position, ref.velocity, self.kp, self.kd, self.effort_limit, self.period,
            self.substeps, self.plant.kernel_args, self.nominal.kernel_args, int(self.dynamics),
            self.error_envelope)
        return TrialRecord(trial, ref, q, qd, u_ff, u, effort, levels,
                           None if abort < 0 else int(abort))


@dataclass
class RunResult:
    """Every trial of one run and what was learned."""

    mass_uncertainty: float
    law: str
    error_bound: float
    records: list[TrialRecord] = field(default_factory=list)
    final: FeedforwardUpdate | None = None
    """The feed-forward learned from the last trial (what trial K+1 would use)."""
    resumed: int = 0
    """Trials restored from the store rather than run (0: none)."""

    @property
    def aborted(self) -> list[int]:
        """Trial numbers aborted by the error envelope (nothing learned from them)."""
        return [r.trial for r in self.records if r.aborted]

    @property
    def max_abs_errors(self) -> np.ndarray:
        """(K, joints) table of max |e| per trial and joint."""
        return np.array([r.max_abs_error for r in self.records])

    @property
    def max_abs_feedforward(self) -> np.ndarray:
        """(K, joints) table of max |u_ff| per trial and joint."""
        return np.array([np.max(np.abs(r.feedforward), axis=0) for r in self.records])

    @property
    def max_abs_effort(self) -> np.ndarray:
        """(K, joints) table of max |effort| per trial and joint."""
        return np.array([np.max(np.abs(r.effort), axis=0) for r in self.records])

    def iterations_to_bound(self) -> IterationsToBound:
        """First and settled trial per joint within ``error_bound``."""
        return iterations_to_bound(self.max_abs_errors, self.error_bound)


def run_trials(config: Config, mass_uncertainty: float | None = None,
               trials: int | None = None, law: str | None = None,
               on_trial: Callable[[TrialRecord], None] | None = None,
               learning_law: LearningLaw | None = None,
               store: Path | str | None = None, resume: bool = False) -> RunResult:
    """Run K trials of the experiment in-process, learning between trials.

    ``law`` names a law of the config (``sign``/``linear``); ``learning_law`` passes any other
    :class:`LearningLaw`. ``on_trial`` is called after each trial run now (progress, logging).
    A trial aborted by the error envelope is kept (marked) but not learned from: the next trial
    reuses its feed-forward. With ``store`` (a root directory, :class:`RunStore`) every trial
    and the feed-forward it led to are saved before the next trial starts; with ``resume`` the
    trials already stored under this run's learning key are restored (bit for bit) and the run
    continues after the last one. A store that already holds trials without ``resume`` is an
    error (nothing is overwritten).
    """
    experiment = Experiment(config, mass_uncertainty)
    chosen = learning_law or build_law(config, law)
    count = int(trials if trials is not None else config["max_trials"])
    result = RunResult(experiment.mass_uncertainty, law or config["law"],
                       float(config["error_bound"]))
    update = FeedforwardUpdate(chosen.initial_feedforward(experiment.reference), None)
    run_store: RunStore | None = None
    if store is not None:
        effective = config.replace({"mass_uncertainty": experiment.mass_uncertainty,
                                    "law": result.law})
        run_store = RunStore(store, effective, experiment.reference)
        if run_store.completed and not resume:
            raise StoreError(f"{run_store.directory}: already holds {run_store.completed} "
                             "trials of this run; resume it or use another store")
        for stored in run_store.load()[:count]:
            result.records.append(stored.record)
            update = stored.next_update
        result.resumed = len(result.records)
    for k in range(len(result.records) + 1, count + 1):
        record = experiment.run_trial(update.feedforward, k, update.levels)
        if not record.aborted:
            update = chosen.update(record)
            if not np.all(np.isfinite(update.feedforward)):
                raise SafetyError(f"trial {k}: the learning law produced a non-finite "
                                  "feed-forward; it was not stored or used")
        if run_store is not None:
            run_store.save(record, update)
        result.records.append(record)
        if on_trial is not None:
            on_trial(record)
    result.final = update
    return result
