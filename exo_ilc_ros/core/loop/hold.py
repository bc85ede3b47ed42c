"""The safe hold's own gains: what brings a (spastic) arm to rest after an abort or a trip.

The hold is the computed torque of :func:`controller.safe_hold_into` around the pose latched at
the abort (the error envelope), the watchdog's trip or a failed homing,

    Q = a_N(q) (K_P,h (q_hold - q) - K_D,h qdot) + c_N(q, qdot), clamped to +-effort_limit,

with its own gains ``safety.hold_kp`` (s^-2) and ``safety.hold_kd`` (s^-1), reached from the
controller's ``control.kp``, ``control.kd`` by a linear ramp over ``safety.hold_ramp`` seconds
(:func:`hold_gains_into`): at the hold's first sample the gains are the controller's, from
``ramp`` samples on exactly the hold's.

Why its own gains. The controller's gains make a hold of ~0.45 N m/rad and ~0.32 N m s/rad on
the forearm, softer than the delayed stretch reflex of a Modified Ashworth 2 arm (1 N m s/rad,
0.1 s late, :mod:`.patient`): the arm kept a 4.4 Hz limit cycle through the hold. Against a
delayed velocity feedback G the hold needs undelayed damping D > G - b (b the arm's own
damping; I s^2 + (D + G e^{-s tau}) s + K has no root crossing the imaginary axis for any delay
tau when D > |G|). Computed torque gives damping a_N(q) K_D,h, and the light mode of the coupled
shoulder-elbow flexion has an inertia down to ~0.01 kg m^2 (the smallest eigenvalue of a_N, at
the straight arm): K_D,h = 60 s^-1 on the elbow brings every MAS 2 abort we provoked or the
study met to rest; 40 left an abort near the straight arm swinging (docs/safety.md "The safe hold").

Why not stiffer. A discrete PD of period T with the command d periods late is stable only for
K_D,h T below ~2 (d = 0), 0.85 (d = 1), 0.52 (d = 2) (critically damped, K_P,h = K_D,h^2 / 4;
:func:`hold_radius`). The ``realistic`` patient's loop is ~2-2.5 periods late at 100 Hz (one
period of actuator delay, a differentiated and 10 ms low-passed velocity): it still comes to
rest with 60 on the elbow (the arm's own damping helps), but 80 on the elbow or 60 on the
shoulder flexion keep it oscillating. The schema refuses hold gains that are not stable with the
command :data:`RULE_DELAY_PERIODS` period late at ``control.period`` (:func:`hold_gain_problem`);
a longer loop must be checked on the arm. A MAS 3 reflex (2 N m s/rad) would need ~120 s^-1 on
the elbow: not reachable at 100 Hz with those sensors, and not claimed.

Why a ramp. Stepping to the stiff damping at the abort brakes a fast arm on a lagging velocity
estimate: under ``realistic`` the elbow overshot to 16 rad/s (5-8 at the abort) and the
shoulder saturated; a 50 ms ramp keeps the peak at the abort's speed and the hold's peak effort
under ``spastic`` at 14 N m instead of the 40 N m limit.

"At rest" (:func:`rest_after_abort`): every joint's true speed below :data:`REST_SPEED` from some
time after the abort to the end of the trial; that time is the time to rest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from .record import TrialRecord

REST_SPEED = 0.05
"""rad/s: every joint's true |qdot| below it counts as at rest."""


@njit(cache=True, error_model="numpy")
def hold_gains_into(m: int, ramp: int, kp: np.ndarray, kd: np.ndarray, hold_kp: np.ndarray,
                    hold_kd: np.ndarray, out: np.ndarray) -> None:
    """The hold's gains at its ``m``-th sample (0: the abort's) into ``out`` (2, n): from the
    controller's (``kp``, ``kd``) to the hold's linearly over ``ramp`` samples, exactly the
    hold's from sample ``ramp`` on (and always with ``ramp`` 0)."""
    n = kp.shape[0]
    if m >= ramp:
        for j in range(n):
            out[0, j] = hold_kp[j]
            out[1, j] = hold_kd[j]
        return
    w = m / ramp
    for j in range(n):
        out[0, j] = kp[j] + w * (hold_kp[j] - kp[j])
        out[1, j] = kd[j] + w * (hold_kd[j] - kd[j])


def ramp_samples(ramp: float, period: float) -> int:
    """``safety.hold_ramp`` (s) in control periods (rounded)."""
    return int(round(float(ramp) / float(period)))


@dataclass(frozen=True)
class RestAfterAbort:
    """How an aborted trial's hold went (true state; per trial, worst joint)."""

    time_to_rest: float
    """s after the abort from which every joint stays below :data:`REST_SPEED` to the trial's
    end (inf: still moving at the end)."""
    tail: float
    """s of hold the trial had after the abort."""
    speed_at_abort: float
    """max_j |qdot_j| at the abort sample (rad/s)."""
    peak_speed: float
    """max_j |qdot_j| from the abort to the end (rad/s)."""
    late_peak_speed: float
    """max_j |qdot_j| from 1 s after the abort to the end (rad/s; NaN: shorter hold)."""
    braking: float
    """max_j max_t |q_j - q_hold,j|: how far the arm got from the latched pose (rad)."""
    final_offset: float
    """max_j |q_j - q_hold,j| at the trial's end (rad)."""
    peak_effort: float
    """max |effort| of the hold (N m)."""
    late_effort: float
    """max |effort| from 1 s after the abort to the end (N m; NaN: shorter hold)."""

    @property
    def at_rest(self) -> bool:
        """Came to rest before the trial's end."""
        return bool(np.isfinite(self.time_to_rest))


def rest_after_abort(record: TrialRecord, period: float) -> RestAfterAbort:
    """The hold of an aborted trial measured on the plant's true state (the measured one where
    the record has none apart); the pose held is the measured one at the abort."""
    a = record.aborted_at
    if a is None:
        raise ValueError(f"trial {record.trial} was not aborted")
    q = record.position if record.true_position is None else record.true_position
    qd = record.velocity if record.true_velocity is None else record.true_velocity
    speed = np.max(np.abs(qd[a:]), axis=1)
    moving = np.flatnonzero(~(speed < REST_SPEED))
    if not moving.size:
        rest = 0.0
    elif moving[-1] == speed.shape[0] - 1:
        rest = float("inf")
    else:
        rest = float(moving[-1] + 1) * period
    late = a + int(round(1.0 / period))
    offset = np.abs(q[a:] - record.position[a])
    effort = np.abs(record.effort[a:])
    return RestAfterAbort(rest, (speed.shape[0] - 1) * period, float(speed[0]),
                          float(np.max(speed)),
                          float(np.max(np.abs(qd[late:]))) if late < qd.shape[0] else np.nan,
                          float(np.max(offset)), float(np.max(offset[-1])),
                          float(np.max(effort)),
                          float(np.max(np.abs(record.effort[late:])))
                          if late < qd.shape[0] else np.nan)
