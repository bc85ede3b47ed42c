"""Reference trajectories: the fifth-order polynomials of eq (14), sampled at the control rate."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class QuinticTrajectory:
    """q_d(t) = a0 + a1 t + ... + a5 t^5 per joint, eq (14).

    ``coefficients[k, j]`` is a_k of joint j. Built by :meth:`rest_to_rest` from the boundary
    conditions of eq (14): positions given at 0 and T, velocities and accelerations zero at both.
    """

    coefficients: np.ndarray
    duration: float

    @classmethod
    def rest_to_rest(cls, start: Sequence[float], goal: Sequence[float],
                     duration: float) -> QuinticTrajectory:
        """The quintic through q(0) = start, q(T) = goal with zero velocity and acceleration at
        both ends, eq (14), in closed form: a0 = q0, a1 = a2 = 0, a3 = 10 d / T^3,
        a4 = -15 d / T^4, a5 = 6 d / T^5 with d = goal - start.

        Closed form rather than a linear solve: a1 and a2 come out exactly 0 (a LAPACK solve gives
        about 1e-16 with a sign that depends on the BLAS kernel the CPU selects, and the sign law
        takes the sign of the error's acceleration at rest, so runs diverged between machines).
        """
        if duration <= 0.0:
            raise ValueError("trajectory duration must be positive")
        q0 = np.asarray(start, dtype=float)
        d = np.asarray(goal, dtype=float) - q0
        t = float(duration)
        zeros = np.zeros_like(q0)
        coefficients = np.vstack([q0, zeros, zeros, 10.0 * d / t**3, -15.0 * d / t**4,
                                  6.0 * d / t**5])
        return cls(coefficients, t)

    @property
    def dof(self) -> int:
        """Number of joints."""
        return int(self.coefficients.shape[1])

    def evaluate(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q_d, qdot_d and qddot_d at times ``t`` (shape ``t.shape + (dof,)``)."""
        tt = np.asarray(t, dtype=float)[..., None]
        a = self.coefficients
        q = a[0] + tt * (a[1] + tt * (a[2] + tt * (a[3] + tt * (a[4] + tt * a[5]))))
        qd = a[1] + tt * (2 * a[2] + tt * (3 * a[3] + tt * (4 * a[4] + tt * 5 * a[5])))
        qdd = 2 * a[2] + tt * (6 * a[3] + tt * (12 * a[4] + tt * 20 * a[5]))
        return q, qd, qdd


@dataclass(frozen=True, eq=False)
class SampledReference:
    """A reference sampled at t_i = i * period, i = 0..N (N = T / period)."""

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    period: float

    @classmethod
    def from_trajectory(cls, trajectory: QuinticTrajectory, period: float) -> SampledReference:
        """Sample ``trajectory`` at the control rate; T must be a whole number of periods."""
        steps = trajectory.duration / period
        n = int(round(steps))
        if n < 1 or abs(steps - n) > 1e-9 * max(1.0, steps):
            raise ValueError("trajectory duration must be a whole number of control periods")
        time = np.arange(n + 1) * period
        q, qd, qdd = trajectory.evaluate(time)
        return cls(time, np.ascontiguousarray(q), np.ascontiguousarray(qd),
                   np.ascontiguousarray(qdd), float(period))

    @property
    def samples(self) -> int:
        """N + 1, the number of samples of one trial."""
        return int(self.time.shape[0])
