"""The closed loop cut at the wire: one plant period, one controller step, a trial rebuilt from
its samples. What the ROS nodes call, so the graph runs exactly the arithmetic of
:func:`integrator.simulate_trial` (same kernels, same order, same doubles).

Sample i of a trial that starts at simulated time ``t0_ns`` is stamped ``t0_ns + i * period_ns``
(integer nanoseconds), so indices are recovered exactly from stamps.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .dynamics import workspace
from .experiment import Experiment
from .integrator import _computed_torque_into, _feedback_into, _rk4_period
from .laws import TrialRecord
from .safety import _outside_envelope, _safe_hold_into
from .trajectory import SampledReference


@njit(cache=True, error_model="numpy")
def _control_into(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                  qd: np.ndarray, kp: np.ndarray, kd: np.ndarray, nominal: tuple,
                  effort_limit: np.ndarray, ws: tuple, u_out: np.ndarray,
                  effort_out: np.ndarray) -> None:
    """u = u_ff + K_P e + K_D e_dot (eq (11)), then Q = a_N u + c_N clamped (eq (16))."""
    _feedback_into(u_ff, q_ref, qd_ref, q, qd, kp, kd, u_out)
    _computed_torque_into(q, qd, u_out, nominal, effort_limit, ws, effort_out)


@njit(cache=True, error_model="numpy")
def _plant_period(effort: np.ndarray, limit: np.ndarray, saturated: np.ndarray, q: np.ndarray,
                  qd: np.ndarray, applied: np.ndarray, period: float, substeps: int,
                  plant: tuple, nominal: tuple, mode: int, ws: tuple, stage: np.ndarray,
                  extra: np.ndarray) -> int:
    """The plant's period in one call: refuse a non-finite effort (-1, nothing changes), count
    saturation, clamp to +-limit into ``applied``, integrate (ZOH, RK4; eq (8)). Returns the
    number of joints beyond the limit."""
    beyond = clamp_counted(effort, limit, saturated, applied)
    if beyond >= 0:
        _rk4_period(q, qd, applied, period, substeps, plant, nominal, mode, ws, stage, extra)
    return beyond


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
        if x >= limit[j] or x <= -limit[j]:
            saturated[j] += 1
            if x > limit[j]:
                x = limit[j]
                beyond += 1
            elif x < -limit[j]:
                x = -limit[j]
                beyond += 1
        out[j] = x
    return beyond


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


class PlantStepper:
    """The simulated arm (true masses) advanced one control period at a time, effort held."""

    def __init__(self, experiment: Experiment) -> None:
        self.experiment = experiment
        n = experiment.reference.position.shape[1]
        self.position = np.empty(n)
        self.velocity = np.empty(n)
        self.applied = np.zeros(n)
        """The effort applied over the last period (after the plant's own limit)."""
        self._ws = workspace(n)
        self._stage = np.empty((10, n))
        self._extra = np.empty(2 * n)
        self._limit = experiment.effort_limit
        self._no_count = np.zeros(n, dtype=np.int64)
        self.reset()

    def reset(self) -> None:
        """Put the arm at x_d(0) (assumption (ii), eq (21)), no effort applied yet."""
        ref = self.experiment.reference
        self.position[:] = ref.position[0]
        self.velocity[:] = ref.velocity[0]
        self.applied[:] = 0.0

    def step(self, effort: np.ndarray, saturated: np.ndarray | None = None) -> int:
        """Hold ``effort`` (clamped to +-effort_limit) over one period: RK4 on the sub-steps.

        ``saturated`` (int64 per joint), if given, counts the joints at or beyond the limit.
        Returns how many joints were beyond it (clamped), or -1, without stepping, for an
        effort that is not one finite value per joint.
        """
        if effort.shape != self.applied.shape:
            return -1
        e = self.experiment
        return int(_plant_period(effort, self._limit, self._no_count if saturated is None
                                 else saturated, self.position, self.velocity, self.applied,
                                 e.period, e.substeps, e.plant.kernel_args,
                                 e.nominal.kernel_args, int(e.dynamics), self._ws, self._stage,
                                 self._extra))


class ControlStep:
    """The computed-torque controller at one sample, into preallocated buffers."""

    def __init__(self, experiment: Experiment) -> None:
        n = experiment.reference.position.shape[1]
        self._nominal = experiment.nominal.kernel_args
        self._kp = experiment.kp
        self._kd = experiment.kd
        self._limit = experiment.effort_limit
        self._ws = workspace(n)
        self.control_input = np.empty(n)
        """u of eq (11) at the last sample."""
        self.effort = np.empty(n)
        """The commanded effort at the last sample (eq (16), clamped)."""

    def __call__(self, u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                 qd: np.ndarray) -> np.ndarray:
        """Effort for the measured (q, qdot) at a sample with these reference values."""
        _control_into(u_ff, q_ref, qd_ref, q, qd, self._kp, self._kd, self._nominal, self._limit,
                      self._ws, self.control_input, self.effort)
        return self.effort


def record_from_samples(experiment: Experiment, trial: int, feedforward: np.ndarray,
                        position: np.ndarray, velocity: np.ndarray,
                        levels: np.ndarray | None = None,
                        reference: SampledReference | None = None,
                        aborted_at: int | None = None) -> TrialRecord:
    """The :class:`TrialRecord` of a trial run elsewhere (the graph), from its sampled states:
    u and effort are formed again exactly as the controller did (the safe hold from
    ``aborted_at`` on, for a trial the error envelope aborted)."""
    ref = reference or experiment.reference
    u_ff = np.ascontiguousarray(feedforward, dtype=float)
    q = np.ascontiguousarray(position, dtype=float)
    qd = np.ascontiguousarray(velocity, dtype=float)
    u, effort = control_inputs(u_ff, ref.position, ref.velocity, q, qd, experiment.kp,
                               experiment.kd, experiment.nominal.kernel_args,
                               experiment.effort_limit, -1 if aborted_at is None
                               else int(aborted_at))
    return TrialRecord(trial, ref, q, qd, u_ff, u, effort, levels, aborted_at)


@njit(cache=True, error_model="numpy")
def control_inputs(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, kp: np.ndarray, kd: np.ndarray, nominal: tuple,
                   effort_limit: np.ndarray, aborted_at: int) -> tuple[np.ndarray, np.ndarray]:
    """u and effort at every sample of a trial from the sampled states, as the controller
    formed them (one :func:`_control_into` per sample, in order); from sample ``aborted_at``
    on (-1: never) the safe hold around q[aborted_at]."""
    n_samples, n = q.shape
    u = np.empty((n_samples, n))
    effort = np.empty((n_samples, n))
    ws = workspace(n)
    for i in range(n_samples):
        if aborted_at < 0 or i < aborted_at:
            _control_into(u_ff[i], q_ref[i], qd_ref[i], q[i], qd[i], kp, kd, nominal,
                          effort_limit, ws, u[i], effort[i])
        else:
            _safe_hold_into(q[aborted_at], q[i], qd[i], kp, kd, nominal, effort_limit, ws,
                            u[i], effort[i])
    return u, effort


class GuardedControlStep(ControlStep):
    """:class:`ControlStep` with the error envelope and the safe hold, one sample at a time,
    the arithmetic of :func:`safety.simulate_trial_guarded`: at the first sample outside the
    envelope (:meth:`outside`) the caller latches the hold pose (:meth:`hold_at`) and commands
    :meth:`hold` from then on."""

    def __init__(self, experiment: Experiment) -> None:
        super().__init__(experiment)
        self.envelope = np.asarray(experiment.error_envelope, dtype=float).copy()
        self.q_hold = np.empty(experiment.reference.position.shape[1])

    def outside(self, q_ref: np.ndarray, q: np.ndarray) -> bool:
        """True if any |q_ref_j - q_j| exceeds the envelope (or is not finite)."""
        return bool(_outside_envelope(q_ref, q, self.envelope))

    def hold_at(self, q: np.ndarray) -> None:
        """Latch the pose the safe hold keeps."""
        self.q_hold[:] = q

    def hold(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The safe-hold effort at (q, qdot) around the latched pose (clamped)."""
        _safe_hold_into(self.q_hold, q, qd, self._kp, self._kd, self._nominal, self._limit,
                        self._ws, self.control_input, self.effort)
        return self.effort
