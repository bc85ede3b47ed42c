"""The plant one control period at a time (the plant_simulator node's arm): the same kernels
as the in-process trial, so the graph's plant equals it bit for bit."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from .patient import (
    PatientLearning,
    PatientTrial,
    TrialDraws,
    measure_into,
    patient_plant_period,
    patient_trial,
    start_state_into,
)
from .plant import plant_integration, plant_period, plant_period_with_joint_forces
from .setup import LoopSetup


class ArmStepper(Protocol):
    """What a plant node steps: the true arm one control period at a time (our RK4 plant,
    :class:`PlantStepper`, or the exoskeleton strapped to a person,
    ``core.person.strapped.StrappedArm``)."""

    @property
    def position(self) -> np.ndarray:
        """The true q."""

    @property
    def velocity(self) -> np.ndarray:
        """The true qdot."""

    applied: np.ndarray

    def reset(self) -> None:
        """Put the arm at the trials' start, no effort applied."""

    def begin_trial(self, trial: int) -> None:
        """Trial ``trial`` starts at sample 0."""

    def measure(self) -> tuple[np.ndarray, np.ndarray]:
        """What the sensors read at the current sample."""

    def step(self, effort: np.ndarray, saturated: np.ndarray | None = None) -> int:
        """Hold ``effort`` over one period (-1: refused)."""


class PlantStepper:
    """The simulated arm (true masses) advanced one control period at a time, effort held,
    with the virtual patient of the experiment's config (:mod:`.patient`): the same kernels as
    :func:`trial.simulate_trial_guarded`, so the graph's plant equals the in-process trial."""

    def __init__(self, experiment: LoopSetup) -> None:

        self.experiment = experiment
        n = experiment.reference.position.shape[1]
        samples = experiment.reference.samples
        self.position = np.empty(n)
        self.velocity = np.empty(n)
        """The true state of the arm."""
        self.applied = np.zeros(n)
        """The effort applied over the last period (after the plant's own limit)."""
        self._integration = plant_integration(
            experiment.period, experiment.substeps, experiment.plant.kernel_args,
            experiment.nominal.kernel_args, int(experiment.dynamics))
        self._total = np.empty(n)
        self._limit = experiment.effort_limit
        self._no_count = np.zeros(n, dtype=np.int64)
        self.patient = experiment.patient
        self.trial: int | None = None
        """The trial whose draws the patient uses (None: none begun since the reset)."""
        self.index = 0
        """The sample the arm is at within the trial."""
        self._draws = TrialDraws(np.zeros((2, 0, 0)), np.zeros((2, 0)), np.zeros(2))
        self._patient_trial: PatientTrial | None = None
        """The patient in the trial begun last (:meth:`begin_trial`)."""
        self._memory = np.zeros((3, n))
        self._measured_position = np.empty(n)
        self._measured_velocity = np.empty(n)
        self._no_torque = np.zeros((0, 0))
        self._learning: Any = None
        self._true = np.empty((samples, n))
        self._runs: dict[int, np.ndarray] = {}
        """A learning patient: the true error of the last run of each trial that reached its
        last sample (the patient learns from it when the next trial begins)."""
        if self.patient.learns:
            self._learning = PatientLearning(self.patient, samples)
        self.reset()

    def reset(self) -> None:
        """Put the arm at x_d(0) (assumption (ii), eq (21)), no effort applied yet."""
        ref = self.experiment.reference
        self.position[:] = ref.position[0]
        self.velocity[:] = ref.velocity[0]
        self.applied[:] = 0.0
        self.trial = None
        self.index = 0

    def begin_trial(self, trial: int) -> None:
        """Trial ``trial`` starts at sample 0: the patient's draws of that trial, the start
        state x_d(0) plus its offset, the patient's memory cleared (a no-op without patient).
        A learning patient first learns from the last run of every earlier trial it has not
        learned from (ValueError if this plant did not run one: the graph cannot resume it); a
        rerun of trial k starts from the same learned state as its first run."""

        self.reset()
        learning = self._learning
        if learning is not None:
            while learning.learned_through < trial - 1:
                done = learning.learned_through + 1
                if done not in self._runs:
                    raise ValueError(f"the learning patient has not run trial {done} here, so "
                                     f"it cannot begin trial {trial} (its adaptation lives in "
                                     "this plant: no resume through the graph)")
                learning.learn(done, self._runs.pop(done))
        self.trial = int(trial)
        if not self.patient.enabled:
            return
        ref = self.experiment.reference
        self._draws = self.patient.draws(trial, ref.samples)
        self._patient_trial = patient_trial(self.patient, self._draws, ref.position,
                                            ref.velocity, self._learned())
        self._memory = self._patient_trial.memory
        start_state_into(ref.position[0], ref.velocity[0], self._draws.initial, self.position,
                         self.velocity)

    def measure(self) -> tuple[np.ndarray, np.ndarray]:
        """What the sensors read at the current sample (:func:`patient.measure_into`; the true
        state itself without sensor effects). Call once per sample, before :meth:`step` (a
        learning patient keeps the true state here for what it learns)."""
        if self._learning is not None and self.trial is not None:
            self._true[self.index] = self.position
            if self.index == self.experiment.reference.samples - 1:
                self._runs[self.trial] = self.experiment.reference.position - self._true
        if not self.patient.measures or self.trial is None:
            return self.position, self.velocity

        measure_into(self.index, self.position, self.velocity, self.patient.scalars,
                     self._draws.noise, self._memory, self._measured_position,
                     self._measured_velocity)
        return self._measured_position, self._measured_velocity

    def step(self, effort: np.ndarray, saturated: np.ndarray | None = None) -> int:
        """Hold ``effort`` (clamped to +-effort_limit) over one period: RK4 on the sub-steps,
        with the patient once a trial has begun (:meth:`begin_trial`), with a URDF arm's own
        joint forces (``model.urdf_joint_dynamics: apply``) always.

        ``saturated`` (int64 per joint), if given, counts the joints at or beyond the limit.
        Returns how many joints were beyond it (clamped), or -1, without stepping, for an
        effort that is not one finite value per joint.
        """
        if effort.shape != self.applied.shape:
            return -1
        e = self.experiment
        counts = self._no_count if saturated is None else saturated
        if self.patient.enabled and self._patient_trial is not None and self.trial is not None \
                and self.index + 1 < e.reference.samples:
            beyond = int(patient_plant_period(
                self.index, effort, self._limit, counts, self.position, self.velocity,
                self.applied, self._integration, self._patient_trial))
        elif self.patient.arm_forces:  # a URDF arm's own joint forces act between trials too
            beyond = int(plant_period_with_joint_forces(
                effort, self._limit, counts, self.position, self.velocity, self.applied,
                self._integration, self.patient.arm_joint, self.patient.inverse_stribeck,
                self._total))
        else:
            beyond = int(plant_period(effort, self._limit, counts, self.position,
                                      self.velocity, self.applied, self._integration))
        if beyond >= 0:
            self.index += 1
        return beyond

    def _learned(self) -> np.ndarray:
        return self._no_torque if self._learning is None else self._learning.torque
