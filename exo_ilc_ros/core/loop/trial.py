"""One trial of the closed loop in-process (controller + plant, compiled), and a trial run
elsewhere (the graph) rebuilt from its samples with the same arithmetic.

The trial is the controller of :mod:`.controller` and the plant of :mod:`.plant` called in the
order the graph calls them (same kernels, same order, same doubles), so the in-process runner
and the ROS graph agree bit for bit. Sample i of a trial that starts at simulated time ``t0_ns``
is stamped ``t0_ns + i * period_ns`` (integer nanoseconds), so indices are recovered exactly
from stamps (:func:`period_ns`, :func:`sample_index`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..reference.trajectory import SampledReference
from .controller import (
    Controller,
    Guard,
    Setpoint,
    controller_of,
    feedback_control_into,
    guarded_control_into,
    hold_into,
)
from .patient import PatientTrial, measure_into, patient_period, start_state_into
from .plant import PlantIntegration, clamp, finite_state, rk4_period
from .record import TrialRecord
from .setup import LoopSetup


@njit(cache=True, error_model="numpy")
def simulate_trial_guarded(u_ff: np.ndarray, joint_force: np.ndarray, controller: Controller,
                           integration: PlantIntegration, patient: PatientTrial
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int,
                                      np.ndarray, np.ndarray]:
    """One trial at the samples t_i = i * period, i = 0..N, of the reference
    ``patient.q_ref``, ``patient.qd_ref``, guarded by the error envelope.

    Starts at x_d(0) (assumption (ii), eq (21)). At each sample the controller reads
    (q, qdot), forms u_i by eq (11) and the effort by eq (16) (:func:`controller.control_into`)
    with the identified joint forces ``joint_force[i]`` (N m; zeros: the paper's controller);
    the plant applies its own limit (a no-op after the controller's clamp) and holds the effort
    over [t_i, t_i+1) (eq (8), :func:`plant.rk4_period`). The command at t_N is recorded but
    never applied. At the first sample outside the envelope the trial is aborted: that sample
    and every later one command the safe hold around the pose measured there (the loop keeps
    integrating so the record shows the hold), with the hold's own gains reached over
    ``controller.hold_ramp`` samples (:func:`hold.hold_gains_into`).

    The virtual patient (:mod:`.patient`; off when ``patient.scalars`` is empty, then none of
    it runs): the trial starts at x_d(0) plus ``patient.initial``, the controller (and the
    envelope) reads the measured state (:func:`patient.measure_into`) and the plant steps with
    :func:`patient.patient_period` (``patient.learned``: a learning patient's torque per
    sample). A plant state that is not finite (the plant diverged, :mod:`.divergence`) stops
    the trial at the sample it is seen: that sample and every later one are NaN in every log,
    and the trial counts as aborted there unless the envelope aborted it before
    (:func:`divergence.plant_divergence` tells the two apart).
    Returns the measured q, qdot, u, effort, the abort index (-1: not aborted) and the true
    q, qdot (the same arrays as the measured ones when the patient is off).
    """
    q_ref = patient.q_ref
    qd_ref = patient.qd_ref
    effort_limit = controller.torque.effort_limit
    n_samples, n = u_ff.shape
    q_log = np.empty((n_samples, n))
    qd_log = np.empty((n_samples, n))
    u_log = np.empty((n_samples, n))
    effort_log = np.empty((n_samples, n))
    applied = np.empty(n)
    q = q_ref[0].copy()
    qd = qd_ref[0].copy()
    on = patient.scalars.shape[0] > 0
    if on:
        start_state_into(q_ref[0], qd_ref[0], patient.initial, q, qd)
        q_true = np.empty((n_samples, n))
        qd_true = np.empty((n_samples, n))
    else:
        q_true = q_log
        qd_true = qd_log
    guard = Guard(np.array([-1, 0], dtype=np.int64), q.copy(), np.empty((2, n)),
                  np.zeros((5, n)))  # controller.guard_of
    state = guard.state  # controller.guard_state()
    for i in range(n_samples):
        if on:
            q_true[i] = q
            qd_true[i] = qd
            measure_into(i, q, qd, patient.scalars, patient.noise, patient.memory, q_log[i],
                         qd_log[i])
        else:
            q_log[i] = q
            qd_log[i] = qd
        if not finite_state(q, qd):  # the plant diverged: stop here (plant.finite_state)
            state[0] = i if state[0] < 0 else state[0]
            for k in range(i, n_samples):
                for j in range(n):
                    q_log[k, j] = np.nan
                    qd_log[k, j] = np.nan
                    u_log[k, j] = np.nan
                    effort_log[k, j] = np.nan
                    q_true[k, j] = np.nan
                    qd_true[k, j] = np.nan
            break
        guarded_control_into(i, False, Setpoint(u_ff[i], q_ref[i], qd_ref[i]), q_log[i],
                             qd_log[i], joint_force[i], controller, guard, u_log[i],
                             effort_log[i])
        if i + 1 < n_samples:
            for j in range(n):
                applied[j] = clamp(effort_log[i, j], effort_limit[j])
            if on:
                patient_period(i, q, qd, applied, integration, patient)
            else:
                rk4_period(q, qd, applied, integration)
    return q_log, qd_log, u_log, effort_log, state[0], q_true, qd_true


@njit(cache=True, error_model="numpy")
def control_inputs(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, joint_force: np.ndarray, controller: Controller,
                   aborted_at: int) -> tuple[np.ndarray, np.ndarray]:
    """u and effort at every sample of a trial from the sampled states, as the controller
    formed them (one :func:`controller.control_into` per sample, in order, with the joint
    forces ``joint_force[i]``); from sample ``aborted_at`` on (-1: never) the safe hold around
    q[aborted_at] with its gains (ramped as :func:`simulate_trial_guarded` does)."""
    n_samples, n = q.shape
    u = np.empty((n_samples, n))
    effort = np.empty((n_samples, n))
    guard = Guard(np.array([-1, 0], dtype=np.int64), q[aborted_at], np.empty((2, n)),
                  np.zeros((5, n)))
    for i in range(n_samples):
        if aborted_at < 0 or i < aborted_at:
            feedback_control_into(i, Setpoint(u_ff[i], q_ref[i], qd_ref[i]), q[i], qd[i],
                                  joint_force[i], controller, guard, u[i], effort[i])
        else:
            hold_into(guard, q[i], qd[i], controller, u[i], effort[i])
    return u, effort


def record_from_samples(experiment: LoopSetup, trial: int, feedforward: np.ndarray,
                        position: np.ndarray, velocity: np.ndarray,
                        levels: np.ndarray | None = None,
                        reference: SampledReference | None = None,
                        aborted_at: int | None = None,
                        true_position: np.ndarray | None = None,
                        true_velocity: np.ndarray | None = None,
                        joint_force: np.ndarray | None = None) -> TrialRecord:
    """The :class:`TrialRecord` of a trial run elsewhere (the graph), from its sampled
    (measured) states: u and effort are formed again exactly as the controller did (the safe
    hold from ``aborted_at`` on, for a trial the error envelope aborted; ``joint_force``: the
    identified joint forces it added, None: none); ``true_position``,
    ``true_velocity``: the plant's true state when the sensors differ from it. The record owns
    copies of the arrays (a caller's sample buffers may be reused for the next trial). Over 10
    parameters because each optional part of a :class:`TrialRecord` a graph's trial may carry
    is one keyword with its default (None: the trial has none)."""
    ref = reference or experiment.reference
    u_ff = np.array(feedforward, dtype=float, order="C")
    q = np.array(position, dtype=float, order="C")
    qd = np.array(velocity, dtype=float, order="C")
    force = np.zeros(q.shape) if joint_force is None else \
        np.array(joint_force, dtype=float, order="C")
    u, effort = control_inputs(u_ff, ref.position, ref.velocity, q, qd, force,
                               controller_of(experiment),
                               -1 if aborted_at is None else int(aborted_at))
    return TrialRecord(trial, ref, q, qd, u_ff, u, effort, levels, aborted_at,
                       None if true_position is None
                       else np.array(true_position, dtype=float, order="C"),
                       None if true_velocity is None
                       else np.array(true_velocity, dtype=float, order="C"),
                       None if joint_force is None else force)


def period_ns(period: float) -> int:
    """The control period in integer nanoseconds (the stamp step of the samples)."""
    return int(round(period * 1e9))


def sample_index(stamp_ns: int, t0_ns: int, step_ns: int, samples: int) -> int | None:
    """Index i of the sample stamped ``stamp_ns`` in a trial starting at ``t0_ns``, or None if
    the stamp is not one of the trial's ``samples`` sample times."""
    offset = stamp_ns - t0_ns
    if offset < 0 or offset % step_ns:
        return None
    i = offset // step_ns
    return i if i < samples else None
