"""Safety in the loop, ROS-free: error envelope and safe hold, effort saturation, watchdog.

Error envelope (``safety.error_envelope``): at every sample the controller compares
|e_j| = |q_d,j - q_j| with the envelope of joint j. At the first sample where any joint is
outside (or the state is not finite) the trial is aborted *at that sample*: from it on the effort
is the **safe hold** and the trial record carries ``aborted_at`` = that index; the supervisor
does not learn from an aborted trial (the next trial reuses the same feed-forward).

Safe hold: the same computed-torque controller with the reference frozen at the pose measured at
the abort, zero reference velocity and no feed-forward:

    Q = a_N(q) (K_P (q_hold - q) - K_D qdot) + c_N(q, qdot), clamped to +-effort_limit,

i.e. nominal gravity (and Coriolis) compensation at the current pose, plus the controller's own
PD gains as stiffness and damping around the abort pose. It brings the arm to rest near where the
fault was seen instead of following the reference on or letting the limb drop; with mass
uncertainty delta it rests with a small gravity sag (delta times the gravity torque over K_P).

The simulated plant applies the effort limit again (``clamp_effort``): in-process it never
changes a value (the controller already clamped), on the wire it protects against any publisher.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from numba import njit

from .dynamics import workspace
from .integrator import _computed_torque_into, _feedback_into, _rk4_period


@njit(cache=True, error_model="numpy")
def _outside_envelope(q_ref: np.ndarray, q: np.ndarray, envelope: np.ndarray) -> bool:
    for j in range(q.shape[0]):  # noqa: SIM110  (a loop numba compiles)
        if not abs(q_ref[j] - q[j]) <= envelope[j]:  # NaN counts as outside
            return True
    return False


@njit(cache=True, error_model="numpy")
def _safe_hold_into(q_hold: np.ndarray, q: np.ndarray, qd: np.ndarray, kp: np.ndarray,
                    kd: np.ndarray, nominal: tuple, effort_limit: np.ndarray, ws: tuple,
                    u_out: np.ndarray, effort_out: np.ndarray) -> None:
    zero = np.zeros(q.shape[0])
    _feedback_into(zero, q_hold, zero, q, qd, kp, kd, u_out)
    _computed_torque_into(q, qd, u_out, nominal, effort_limit, ws, effort_out)


@njit(cache=True, error_model="numpy")
def safe_hold_effort(q_hold: np.ndarray, q: np.ndarray, qd: np.ndarray, kp: np.ndarray,
                     kd: np.ndarray, nominal: tuple, effort_limit: np.ndarray) -> np.ndarray:
    """The safe-hold effort at (q, qdot) around the pose ``q_hold`` (module docstring)."""
    n = q.shape[0]
    u = np.empty(n)
    out = np.empty(n)
    _safe_hold_into(q_hold, q, qd, kp, kd, nominal, effort_limit, workspace(n), u, out)
    return out


@njit(cache=True, error_model="numpy")
def simulate_trial_guarded(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray,
                           kp: np.ndarray, kd: np.ndarray, effort_limit: np.ndarray,
                           period: float, substeps: int, plant: tuple, nominal: tuple, mode: int,
                           envelope: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`integrator.simulate_trial` with the error envelope and the plant's own limit.

    Identical doubles to ``simulate_trial`` while every |e_j| <= envelope_j. At the first sample
    outside, the trial is aborted: that sample and every later one command the safe hold around
    the pose measured there (the loop keeps integrating so the record shows the hold). Returns
    q, qdot, u, effort and the abort index (-1: not aborted).
    """
    n_samples, n = u_ff.shape
    q_log = np.empty((n_samples, n))
    qd_log = np.empty((n_samples, n))
    u_log = np.empty((n_samples, n))
    effort_log = np.empty((n_samples, n))
    ws = workspace(n)
    stage = np.empty((10, n))
    extra = np.empty(2 * n)
    applied = np.empty(n)
    q = q_ref[0].copy()
    qd = qd_ref[0].copy()
    q_hold = q.copy()
    abort = -1
    for i in range(n_samples):
        q_log[i] = q
        qd_log[i] = qd
        if abort < 0 and _outside_envelope(q_ref[i], q, envelope):
            abort = i
            q_hold[:] = q
        if abort < 0:
            _feedback_into(u_ff[i], q_ref[i], qd_ref[i], q, qd, kp, kd, u_log[i])
            _computed_torque_into(q, qd, u_log[i], nominal, effort_limit, ws, effort_log[i])
        else:
            _safe_hold_into(q_hold, q, qd, kp, kd, nominal, effort_limit, ws, u_log[i],
                            effort_log[i])
        if i + 1 < n_samples:
            for j in range(n):  # the plant's own limit (a no-op after the controller's clamp)
                applied[j] = min(max(effort_log[i, j], -effort_limit[j]), effort_limit[j])
            _rk4_period(q, qd, applied, period, substeps, plant, nominal, mode, ws, stage, extra)
    return q_log, qd_log, u_log, effort_log, abort


def outside_envelope(error: np.ndarray, envelope: np.ndarray) -> bool:
    """True if any |e_j| exceeds the envelope or is not finite (one sample, per joint)."""
    e = np.abs(np.asarray(error, dtype=float))
    return bool(np.any(~(e <= np.asarray(envelope, dtype=float))))


def clamp_effort(effort: np.ndarray, limit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``effort`` clipped to +-``limit`` and the per-joint mask of saturated joints
    (|effort| >= limit). Non-finite values must be rejected before (``validation``)."""
    effort = np.asarray(effort, dtype=float)
    limit = np.asarray(limit, dtype=float)
    return np.clip(effort, -limit, limit), np.abs(effort) >= limit


def saturation_counts(effort: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Per joint, the number of samples of an (N+1, joints) effort log at the limit."""
    return np.asarray(np.sum(np.abs(np.asarray(effort)) >= np.asarray(limit), axis=0))


@dataclass
class SaturationReport:
    """Running count of saturated samples per joint (the plant's saturation report)."""

    limit: np.ndarray
    samples: int = 0
    saturated: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.limit = np.asarray(self.limit, dtype=float)
        self.saturated = np.zeros(self.limit.shape[0], dtype=np.int64)

    def apply(self, effort: np.ndarray) -> np.ndarray:
        """Clamp one effort command, count it; returns the effort to apply."""
        clipped, mask = clamp_effort(effort, self.limit)
        self.samples += 1
        self.saturated += mask
        return clipped

    def as_values(self, joint_names: list[str]) -> list[tuple[str, str]]:
        """Key-values for a diagnostic status: samples and saturated samples per joint."""
        return [("samples", str(self.samples))] + [
            (f"saturated/{name}", str(int(c))) for name, c in zip(joint_names, self.saturated,
                                                                   strict=True)]


class WatchdogState(Enum):
    """Where the watchdog is."""

    IDLE = "idle"
    """Not expecting input (between trials)."""
    RUNNING = "running"
    """Input is arriving in time."""
    TIMED_OUT = "timed_out"
    """No input for longer than the timeout: command the safe hold (latched until re-armed)."""


class Watchdog:
    """No input for ``periods`` control periods -> TIMED_OUT (latched until :meth:`arm`).

    Times are integer nanoseconds of any monotonic clock the caller chooses (a steady clock in
    lock-step mode, where simulated time stands still without input). The controller feeds it
    with every /joint_states message and commands the safe hold while :attr:`tripped`; the plant
    feeds it with every command and stops holding the last command once tripped.
    """

    def __init__(self, periods: int, period_ns: int, min_timeout_ns: int = 0) -> None:
        if periods < 1 or period_ns < 1 or min_timeout_ns < 0:
            raise ValueError(f"watchdog needs periods >= 1, period_ns >= 1 and min_timeout_ns "
                             f">= 0, got {periods}, {period_ns} and {min_timeout_ns}")
        self.timeout_ns = max(int(periods) * int(period_ns), int(min_timeout_ns))
        """``periods`` control periods, but never less than ``min_timeout_ns``."""
        self.state = WatchdogState.IDLE
        self.last_ns = 0
        self.trips = 0
        """How many times it timed out since construction."""
        self.late = 0
        """Inputs that arrived while timed out (ignored until re-armed)."""

    @property
    def tripped(self) -> bool:
        """True while the safe hold must be commanded."""
        return self.state is WatchdogState.TIMED_OUT

    def arm(self, now_ns: int) -> None:
        """Start expecting input (trial start); clears a trip."""
        self.state = WatchdogState.RUNNING
        self.last_ns = int(now_ns)

    def disarm(self) -> None:
        """Stop expecting input (trial end)."""
        self.state = WatchdogState.IDLE

    def feed(self, now_ns: int) -> bool:
        """An input arrived; returns False if it is ignored (timed out or idle)."""
        if self.state is WatchdogState.TIMED_OUT:
            self.late += 1
            return False
        if self.state is WatchdogState.IDLE:
            return False
        self.check(now_ns)
        if self.tripped:
            self.late += 1
            return False
        self.last_ns = int(now_ns)
        return True

    def check(self, now_ns: int) -> bool:
        """Call periodically; returns True exactly once, on the transition to TIMED_OUT."""
        if self.state is WatchdogState.RUNNING and int(now_ns) - self.last_ns > self.timeout_ns:
            self.state = WatchdogState.TIMED_OUT
            self.trips += 1
            return True
        return False

    def as_values(self) -> list[tuple[str, str]]:
        """Key-values for a diagnostic status."""
        return [("state", self.state.value), ("trips", str(self.trips)),
                ("late_inputs", str(self.late)), ("timeout_ns", str(self.timeout_ns))]
