"""The simulated arm: RK4 integration with the effort held over each period, its effort limit and
saturation count. The one clamp rule (:func:`clamp`) lives here; the controller clamps its
command with it too, so the plant's own limit never changes a command the controller formed.

One control period: the effort Q is held (ZOH) while the true plant, a(q) qdd + c(q, qdot) = Q,
eq (8), is integrated by classic RK4 on ``substeps`` equal sub-steps. ``mode`` selects the plant:
:class:`PlantDynamics` ``FULL`` (true masses) or ``PAPER_APPROXIMATION`` (eqs (17)-(18)).
``plant`` and ``nominal`` are the models' ``kernel_args`` tuples.
"""

from __future__ import annotations

from enum import IntEnum
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from .dynamics import forward_dynamics_into, inertia_and_bias_into, workspace
from .joint_forces import passive_effort_into

if TYPE_CHECKING:
    from .experiment import Experiment


class PlantDynamics(IntEnum):
    """How the simulated plant answers an effort."""

    FULL = 0
    """qdd = a(q)^-1 (Q - c(q, qdot)) with the true (uncertain) masses: eq (15) exactly."""
    PAPER_APPROXIMATION = 1
    """qdd = a_N^-1 (Q - c_N) + eta, eta = -a^-1 (c - c_N): eq (17)-(18) with a^-1 a_N ~ I."""


@njit(cache=True, error_model="numpy")
def clamp(x: float, limit: float) -> float:
    """``x`` limited to [-limit, limit]: the one effort clamp (controller and plant). A NaN
    passes through unchanged (non-finite efforts are refused before, see :func:`clamp_counted`)."""
    if x > limit:
        return limit
    if x < -limit:
        return -limit
    return x


@njit(cache=True, error_model="numpy")
def at_limit(x: float, limit: float) -> bool:
    """True if the effort ``x`` is saturated: |x| >= limit (the saturation count's rule)."""
    return x >= limit or x <= -limit


@njit(cache=True, error_model="numpy")
def clamp_counted(effort: np.ndarray, limit: np.ndarray, saturated: np.ndarray,
                  out: np.ndarray) -> int:
    """``effort`` clamped to +-limit into ``out``, joints at or beyond the limit counted in
    ``saturated``; returns how many were beyond it, or -1 (nothing written or counted) for a
    non-finite effort."""
    n = effort.shape[0]
    for j in range(n):
        if not np.isfinite(effort[j]):
            return -1
    beyond = 0
    for j in range(n):
        x = effort[j]
        if at_limit(x, limit[j]):
            saturated[j] += 1
        out[j] = clamp(x, limit[j])
        if out[j] != x:
            beyond += 1
    return beyond


@njit(cache=True, error_model="numpy")
def saturation_counts(effort: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Per joint, the number of samples of an (N+1, joints) effort log at the limit."""
    n_samples, n = effort.shape
    counts = np.zeros(n, dtype=np.int64)
    for i in range(n_samples):
        for j in range(n):
            if at_limit(effort[i, j], limit[j]):
                counts[j] += 1
    return counts


@njit(cache=True, error_model="numpy")
def _acceleration_into(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, plant: tuple,
                       nominal: tuple, mode: int, ws: tuple, extra: np.ndarray,
                       out: np.ndarray) -> None:
    if mode == 0:
        forward_dynamics_into(q, qd, effort, *plant, ws, out)
        return
    n = q.shape[0]
    # eta = -a^-1 (c - c_N), eq (18): the plant's answer to zero effort minus the nominal one
    cn = extra[n:2 * n]
    inertia_and_bias_into(q, qd, *nominal, ws, cn)
    forward_dynamics_into(q, qd, cn, *plant, ws, extra[:n])  # a^-1 (c_N - c)
    forward_dynamics_into(q, qd, effort, *nominal, ws, out)  # a_N^-1 (Q - c_N)
    for j in range(n):
        out[j] += extra[j]


@njit(cache=True, error_model="numpy", inline="always")
def rk4_period_with_joint_forces(q: np.ndarray, qd: np.ndarray, effort: np.ndarray,
                                 period: float, substeps: int, plant: tuple, nominal: tuple,
                                 mode: int, ws: tuple, stage: np.ndarray, extra: np.ndarray,
                                 passive: bool, joint: np.ndarray, inverse_stribeck: float,
                                 total: np.ndarray) -> None:
    """In place: (q, qdot) advanced by one period with ``effort`` held (ZOH), eq (8) integrated
    by classic 4-stage Runge-Kutta on each of ``substeps`` sub-steps; with ``passive``, the
    passive joint forces of eq (6) (:func:`joint_forces.passive_effort_into`, the patient's
    ``joint`` array and 1 / v_s) are added at every stage's state. ``ws`` is a
    :func:`dynamics.workspace`, ``stage`` a (10, n) and ``extra`` a (2n,) scratch array,
    ``total`` (n,) receives the torque each stage integrates (without ``passive``: a copy of
    ``effort``, or ``effort`` itself; ``joint`` is then not read).

    One body for the paper's plant (:func:`rk4_period`) and the patient's
    (:func:`patient.patient_period`), inlined into both. With the true plant (``mode`` 0) each
    stage calls :func:`forward_dynamics_into` directly, with ``plant`` unpacked once before the
    loop: through :func:`_acceleration_into` (or with a ``*plant`` call inside the loop, or a
    helper function per stage, inlined or not) numba increfs and decrefs every array argument
    at every stage, about a third of the cost of a plant evaluation.
    """
    n = q.shape[0]
    h = period / substeps
    masses, axes, offsets, coms, inertias, gravity = plant
    k1v, k2v, k3v, k4v = stage[0], stage[1], stage[2], stage[3]
    q2, v2, q3, v3, q4, v4 = stage[4], stage[5], stage[6], stage[7], stage[8], stage[9]
    if not passive:
        for j in range(n):
            total[j] = effort[j]
    for _ in range(substeps):
        if passive:
            passive_effort_into(q, qd, effort, joint, inverse_stribeck, total)
        if mode == 0:
            forward_dynamics_into(q, qd, total, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k1v)
        else:
            _acceleration_into(q, qd, total, plant, nominal, mode, ws, extra, k1v)
        for j in range(n):
            q2[j] = q[j] + 0.5 * h * qd[j]
            v2[j] = qd[j] + 0.5 * h * k1v[j]
        if passive:
            passive_effort_into(q2, v2, effort, joint, inverse_stribeck, total)
        if mode == 0:
            forward_dynamics_into(q2, v2, total, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k2v)
        else:
            _acceleration_into(q2, v2, total, plant, nominal, mode, ws, extra, k2v)
        for j in range(n):
            q3[j] = q[j] + 0.5 * h * v2[j]
            v3[j] = qd[j] + 0.5 * h * k2v[j]
        if passive:
            passive_effort_into(q3, v3, effort, joint, inverse_stribeck, total)
        if mode == 0:
            forward_dynamics_into(q3, v3, total, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k3v)
        else:
            _acceleration_into(q3, v3, total, plant, nominal, mode, ws, extra, k3v)
        for j in range(n):
            q4[j] = q[j] + h * v3[j]
            v4[j] = qd[j] + h * k3v[j]
        if passive:
            passive_effort_into(q4, v4, effort, joint, inverse_stribeck, total)
        if mode == 0:
            forward_dynamics_into(q4, v4, total, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k4v)
        else:
            _acceleration_into(q4, v4, total, plant, nominal, mode, ws, extra, k4v)
        for j in range(n):
            q[j] = q[j] + (h / 6.0) * (qd[j] + 2.0 * v2[j] + 2.0 * v3[j] + v4[j])
            qd[j] = qd[j] + (h / 6.0) * (k1v[j] + 2.0 * k2v[j] + 2.0 * k3v[j] + k4v[j])


@njit(cache=True, error_model="numpy")
def rk4_period(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, period: float, substeps: int,
               plant: tuple, nominal: tuple, mode: int, ws: tuple, stage: np.ndarray,
               extra: np.ndarray) -> None:
    """In place: (q, qdot) advanced by one period with ``effort`` held (ZOH), eq (8) by classic
    RK4 on the sub-steps: :func:`rk4_period_with_joint_forces` without joint forces (``stage``
    a (10, n), ``extra`` a (2n,) scratch array)."""
    rk4_period_with_joint_forces(q, qd, effort, period, substeps, plant, nominal, mode, ws,
                                 stage, extra, False, stage, 0.0, effort)


@njit(cache=True, error_model="numpy")
def plant_period(effort: np.ndarray, limit: np.ndarray, saturated: np.ndarray, q: np.ndarray,
                 qd: np.ndarray, applied: np.ndarray, period: float, substeps: int,
                 plant: tuple, nominal: tuple, mode: int, ws: tuple, stage: np.ndarray,
                 extra: np.ndarray) -> int:
    """The plant's period in one call: refuse a non-finite effort (-1, nothing changes), count
    saturation, clamp to +-limit into ``applied`` (:func:`clamp_counted`), integrate
    (:func:`rk4_period`, eq (8)). Returns the number of joints beyond the limit."""
    beyond = clamp_counted(effort, limit, saturated, applied)
    if beyond >= 0:
        rk4_period(q, qd, applied, period, substeps, plant, nominal, mode, ws, stage, extra)
    return beyond


@njit(cache=True, error_model="numpy")
def integrate_period(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, period: float,
                     substeps: int, plant: tuple, nominal: tuple,
                     mode: int) -> tuple[np.ndarray, np.ndarray]:
    """(q, qdot) after one control period with ``effort`` held (ZOH), eq (8) by RK4 on the
    sub-steps, as new arrays (no limit applied). The allocating form of :func:`rk4_period`,
    for tests and interactive use."""
    n = q.shape[0]
    q = q.copy()
    qd = qd.copy()
    rk4_period(q, qd, effort, period, substeps, plant, nominal, mode, workspace(n),
               np.empty((10, n)), np.empty(2 * n))
    return q, qd


class PlantStepper:
    """The simulated arm (true masses) advanced one control period at a time, effort held,
    with the virtual patient of the experiment's config (:mod:`.patient`): the same kernels as
    :func:`trial.simulate_trial_guarded`, so the graph's plant equals the in-process trial."""

    def __init__(self, experiment: Experiment) -> None:
        from .patient import TrialDraws

        self.experiment = experiment
        n = experiment.reference.position.shape[1]
        samples = experiment.reference.samples
        self.position = np.empty(n)
        self.velocity = np.empty(n)
        """The true state of the arm."""
        self.applied = np.zeros(n)
        """The effort applied over the last period (after the plant's own limit)."""
        self._ws = workspace(n)
        self._stage = np.empty((10, n))
        self._extra = np.empty(3 * n)
        self._limit = experiment.effort_limit
        self._no_count = np.zeros(n, dtype=np.int64)
        self.patient = experiment.patient
        self.trial: int | None = None
        """The trial whose draws the patient uses (None: none begun since the reset)."""
        self.index = 0
        """The sample the arm is at within the trial."""
        self._draws = TrialDraws(np.zeros((2, 0, 0)), np.zeros((2, 0)), np.zeros(2))
        self._history = np.empty((2, samples, n))
        self._memory = np.zeros((3, n))
        self._held = np.empty(n)
        self._measured_position = np.empty(n)
        self._measured_velocity = np.empty(n)
        self._no_torque = np.zeros((0, 0))
        self._learning: Any = None
        self._true = np.empty((samples, n))
        self._runs: dict[int, np.ndarray] = {}
        """A learning patient: the true error of the last run of each trial that reached its
        last sample (the patient learns from it when the next trial begins)."""
        if self.patient.learns:
            from .patient import PatientLearning

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
        from .patient import start_state_into

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
        start_state_into(ref.position[0], ref.velocity[0], self._draws.initial, self.position,
                         self.velocity)
        self._memory[:] = 0.0

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
        from .patient import measure_into

        measure_into(self.index, self.position, self.velocity, self.patient.scalars,
                     self._draws.noise, self._memory, self._measured_position,
                     self._measured_velocity)
        return self._measured_position, self._measured_velocity

    def step(self, effort: np.ndarray, saturated: np.ndarray | None = None) -> int:
        """Hold ``effort`` (clamped to +-effort_limit) over one period: RK4 on the sub-steps,
        with the patient once a trial has begun (:meth:`begin_trial`).

        ``saturated`` (int64 per joint), if given, counts the joints at or beyond the limit.
        Returns how many joints were beyond it (clamped), or -1, without stepping, for an
        effort that is not one finite value per joint.
        """
        if effort.shape != self.applied.shape:
            return -1
        e = self.experiment
        counts = self._no_count if saturated is None else saturated
        if self.patient.enabled and self.trial is not None \
                and self.index + 1 < e.reference.samples:
            from .patient import patient_plant_period

            ref = e.reference
            beyond = int(patient_plant_period(
                self.index, effort, self._limit, counts, self.position, self.velocity,
                self.applied, ref.position, ref.velocity, e.period, e.substeps,
                e.plant.kernel_args, e.nominal.kernel_args, int(e.dynamics), self._ws,
                self._stage, self._extra, self.patient.joint, self.patient.scalars,
                self._draws.trial_scalars, self._learned(), self._history, self._memory,
                self._held))
        else:
            beyond = int(plant_period(effort, self._limit, counts, self.position,
                                      self.velocity, self.applied, e.period, e.substeps,
                                      e.plant.kernel_args, e.nominal.kernel_args,
                                      int(e.dynamics), self._ws, self._stage, self._extra))
        if beyond >= 0:
            self.index += 1
        return beyond

    def _learned(self) -> np.ndarray:
        return self._no_torque if self._learning is None else self._learning.torque
