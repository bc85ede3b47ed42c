"""One joint's sampled closed loop under computed torque with a mass error (:class:`JointLoop`),
the linearisation :mod:`.factors` explains: a ZOH double integrator of gain g = 1/(1+delta) under
PD, and the trial-to-trial factor of a learning law on it (eq (*) of :mod:`.factors`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ..learning.assist import aan_factor
from ..learning.laws import Memory


@dataclass(frozen=True)
class JointLoop:
    """The sampled loop of one joint: plant gain g = 1/(1+delta), PD gains, period, and the
    patient's linear joint forces per unit of the joint's nominal inertia (eq (6)'s Q^c and
    Q^v: K / a_N,jj in s^-2, B / a_N,jj in s^-1), which act through the same gain g as the
    controller's PD: qdd = g (u - stiffness q - damping qdot), and a delayed stretch reflex
    (:mod:`..loop.patient`, linearised where it is active: G / a_N,jj in s^-1, ``reflex``, on
    the true velocity ``reflex_delay`` periods ago, held over the period as the plant holds it):
    qdd_i = g (u_i - stiffness q_i - damping qdot_i - reflex qdot_{i-d}). In z the reflex is a
    damping that depends on frequency, damping + reflex z^-d.

    ``continuous_patient``: the stiffness and damping act within the period, as the plant
    integrates them (x_{i+1} = A_d x_i + B_d u_i with A_d, B_d the exact discretisation of
    qdd = g (u - stiffness q - damping qdot)), instead of being held with the PD (the default,
    every number before issue 33's reflex). A damping near 1 / T held over a period is a
    sampled-data artefact that destabilises at Nyquist; the plant's is not."""

    gain: float
    kp: float
    kd: float
    period: float
    stiffness: float = 0.0
    damping: float = 0.0
    reflex: float = 0.0
    """G / a_N,jj (s^-1): the stretch reflex's gain per unit of the joint's inertia; 0: none."""
    reflex_delay: int = 0
    """d: the reflex's delay in control periods."""
    continuous_patient: bool = False
    """The patient's stiffness and damping integrated over the period (exact), not held."""

    def discrete(self) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(A_d, B_d, K, D): x_{i+1} = A_d x_i + B_d (u_ff,i - K q_i - D qdot_i - reflex
        qdot_{i-d}), K and D the gains fed back through B_d (the PD's, plus the patient's when
        held)."""
        T, g = self.period, self.gain
        if not self.continuous_patient:
            return (np.array([[1.0, T], [0.0, 1.0]]), g * np.array([T * T / 2.0, T]),
                    self.kp + self.stiffness, self.kd + self.damping)
        augmented = np.zeros((3, 3))
        augmented[0, 1] = 1.0
        augmented[1] = [-g * self.stiffness, -g * self.damping, g]
        exact = expm(augmented * T)
        return exact[:2, :2], exact[:2, 2], self.kp, self.kd

    def spectral_radius(self) -> tuple[float, float]:
        """(max |pole|, that pole's frequency in Hz) of the loop within a trial, the reflex's
        delay line in its state (q, qdot, qdot_{i-1}, ..., qdot_{i-d}): stable when the radius
        is below 1; at or above it eq (*) means nothing (an oscillation grows inside every
        trial, or, bounded by the reflex's threshold and ceiling, keeps its size)."""
        a_d, b_d, k, damping = self.discrete()
        d = int(self.reflex_delay)
        n = 2 + d
        m = np.zeros((n, n))
        m[:2, :2] = a_d - np.outer(b_d, [k, damping])
        if d == 0:
            m[:2, 1] -= b_d * self.reflex
        else:
            m[:2, n - 1] -= b_d * self.reflex
            m[2, 1] = 1.0
            for i in range(3, n):
                m[i, i - 1] = 1.0
        poles = np.linalg.eigvals(m)
        i = int(np.argmax(np.abs(poles)))
        return float(abs(poles[i])), float(abs(np.angle(poles[i])) / (2.0 * np.pi * self.period))

    def closed_loop(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """P_q(z), P_v(z): u_ff -> q and u_ff -> qdot of x_{i+1} = (A - B K) x_i + B u_ff,i.

        Closed form of (zI - A + B K)^-1 B for the ZOH double integrator.
        """
        if self.continuous_patient or self.reflex:
            a_d, b_d, k, damping = self.discrete()
            dz = damping + (self.reflex * z ** -float(self.reflex_delay) if self.reflex
                            else 0.0)
            m11, m12 = z - a_d[0, 0] + b_d[0] * k, -a_d[0, 1] + b_d[0] * dz
            m21, m22 = -a_d[1, 0] + b_d[1] * k, z - a_d[1, 1] + b_d[1] * dz
            det = m11 * m22 - m12 * m21
            return (m22 * b_d[0] - m12 * b_d[1]) / det, (m11 * b_d[1] - m21 * b_d[0]) / det
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
