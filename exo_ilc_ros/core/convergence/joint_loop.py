"""One joint's sampled closed loop under computed torque with a mass error (:class:`JointLoop`),
the linearisation :mod:`.factors` explains: a ZOH double integrator of gain g = 1/(1+delta) under
PD, and the trial-to-trial factor of a learning law on it (eq (*) of :mod:`.factors`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..learning.assist import aan_factor
from ..learning.laws import Memory


@dataclass(frozen=True)
class JointLoop:
    """The sampled loop of one joint: plant gain g = 1/(1+delta), PD gains, period, and the
    patient's linear joint forces per unit of the joint's nominal inertia (eq (6)'s Q^c and
    Q^v: K / a_N,jj in s^-2, B / a_N,jj in s^-1), which act through the same gain g as the
    controller's PD: qdd = g (u - stiffness q - damping qdot)."""

    gain: float
    kp: float
    kd: float
    period: float
    stiffness: float = 0.0
    damping: float = 0.0

    def closed_loop(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """P_q(z), P_v(z): u_ff -> q and u_ff -> qdot of x_{i+1} = (A - B K) x_i + B u_ff,i.

        Closed form of (zI - A + B K)^-1 B for the ZOH double integrator.
        """
        T, g = self.period, self.gain
        b1, b2 = g * T * T / 2.0, g * T
        kp, kd = self.kp + self.stiffness, self.kd + self.damping  # the patient's add to the PD
        # A - B K = [[1 - b1 kp, T - b1 kd], [-b2 kp, 1 - b2 kd]]
        a11, a12 = 1.0 - b1 * kp, T - b1 * kd
        a21, a22 = -b2 * kp, 1.0 - b2 * kd
        det = (z - a11) * (z - a22) - a12 * a21
        pq = ((z - a22) * b1 + a12 * b2) / det
        pv = (a21 * b1 + (z - a11) * b2) / det
        return pq, pv

    def sensitivity(self, z: np.ndarray) -> np.ndarray:
        """S(z) = 1 - K_P P_q - K_D P_v: u_ff -> whole input u (input sensitivity)."""
        pq, pv = self.closed_loop(z)
        return np.asarray(1.0 - self.kp * pq - self.kd * pv)

    def factor(self, frequency_hz: np.ndarray, memory: Memory, gains: tuple[float, float, float],
               q: np.ndarray | None = None, forgetting: float | None = None) -> np.ndarray:
        """|F(e^jw)| of eq (*) in the module docstring, per frequency; with ``forgetting``
        (assist-as-needed on) the worst over its deadband's gate, :func:`.assist.aan_factor`."""
        w = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) * self.period
        z = np.exp(1j * w)
        pq, pv = self.closed_loop(z)
        d = (z - 1.0 / z) / (2.0 * self.period)
        m = 1.0 - self.kp * pq - self.kd * pv if memory is Memory.TOTAL_INPUT else 1.0
        gp, gd, gdd = gains
        f = m - gp * pq - gd * pv - gdd * d * pv
        if forgetting is not None:
            worst = aan_factor(f, m * np.ones_like(z), forgetting)
            return np.asarray(worst if q is None else np.abs(q) * worst)
        if q is not None:
            f = q * f
        return np.asarray(np.abs(f))
