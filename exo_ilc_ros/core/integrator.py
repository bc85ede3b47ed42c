"""Fixed-step RK4 integration of the plant with zero-order-hold effort, and the compiled trial loop.

One control period: the effort Q is held while the true plant, a(q) qdd + c(q, qdot) = Q, eq (8),
is integrated by classic RK4 on ``substeps`` equal sub-steps. ``mode`` selects the plant:
:class:`PlantDynamics` ``FULL`` (true masses) or ``PAPER_APPROXIMATION`` (eq (17)-(18)).

``plant`` and ``nominal`` are the models' ``kernel_args`` tuples.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np
from numba import njit

from .dynamics import forward_dynamics_into, inertia_and_bias_into, workspace


class PlantDynamics(IntEnum):
    """How the simulated plant answers an effort."""

    FULL = 0
    """qdd = a(q)^-1 (Q - c(q, qdot)) with the true (uncertain) masses: eq (15) exactly."""
    PAPER_APPROXIMATION = 1
    """qdd = a_N^-1 (Q - c_N) + eta, eta = -a^-1 (c - c_N): eq (17)-(18) with a^-1 a_N ~ I."""


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


@njit(cache=True, error_model="numpy")
def integrate_period(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, period: float,
                     substeps: int, plant: tuple, nominal: tuple,
                     mode: int) -> tuple[np.ndarray, np.ndarray]:
    """Advance (q, qdot) by one control period with ``effort`` held (ZOH), RK4 on sub-steps."""
    n = q.shape[0]
    ws = workspace(n)
    stage = np.empty((10, n))
    extra = np.empty(2 * n)
    q = q.copy()
    qd = qd.copy()
    _rk4_period(q, qd, effort, period, substeps, plant, nominal, mode, ws, stage, extra)
    return q, qd


@njit(cache=True, error_model="numpy")
def _rk4_period(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, period: float, substeps: int,
                plant: tuple, nominal: tuple, mode: int, ws: tuple, stage: np.ndarray,
                extra: np.ndarray) -> None:
    """In-place RK4 over one period: classic 4-stage Runge-Kutta on each sub-step.

    With the true plant (``mode`` 0) each stage calls :func:`forward_dynamics_into` directly,
    with ``plant`` unpacked once before the loop: through :func:`_acceleration_into` (or with a
    ``*plant`` call inside the loop) numba increfs and decrefs every array argument at every
    stage, about a third of the cost of a plant evaluation.
    """
    n = q.shape[0]
    h = period / substeps
    masses, axes, offsets, coms, inertias, gravity = plant
    k1v, k2v, k3v, k4v = stage[0], stage[1], stage[2], stage[3]
    q2, v2, q3, v3, q4, v4 = stage[4], stage[5], stage[6], stage[7], stage[8], stage[9]
    for _ in range(substeps):
        if mode == 0:
            forward_dynamics_into(q, qd, effort, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k1v)
        else:
            _acceleration_into(q, qd, effort, plant, nominal, mode, ws, extra, k1v)
        for j in range(n):
            q2[j] = q[j] + 0.5 * h * qd[j]
            v2[j] = qd[j] + 0.5 * h * k1v[j]
        if mode == 0:
            forward_dynamics_into(q2, v2, effort, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k2v)
        else:
            _acceleration_into(q2, v2, effort, plant, nominal, mode, ws, extra, k2v)
        for j in range(n):
            q3[j] = q[j] + 0.5 * h * v2[j]
            v3[j] = qd[j] + 0.5 * h * k2v[j]
        if mode == 0:
            forward_dynamics_into(q3, v3, effort, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k3v)
        else:
            _acceleration_into(q3, v3, effort, plant, nominal, mode, ws, extra, k3v)
        for j in range(n):
            q4[j] = q[j] + h * v3[j]
            v4[j] = qd[j] + h * k3v[j]
        if mode == 0:
            forward_dynamics_into(q4, v4, effort, masses, axes, offsets, coms, inertias, gravity,
                                  ws, k4v)
        else:
            _acceleration_into(q4, v4, effort, plant, nominal, mode, ws, extra, k4v)
        for j in range(n):
            q[j] = q[j] + (h / 6.0) * (qd[j] + 2.0 * v2[j] + 2.0 * v3[j] + v4[j])
            qd[j] = qd[j] + (h / 6.0) * (k1v[j] + 2.0 * k2v[j] + 2.0 * k3v[j] + k4v[j])


@njit(cache=True, error_model="numpy")
def _computed_torque_into(q: np.ndarray, qd: np.ndarray, u: np.ndarray, nominal: tuple,
                          effort_limit: np.ndarray, ws: tuple, out: np.ndarray) -> None:
    n = u.shape[0]
    an = inertia_and_bias_into(q, qd, *nominal, ws, out)
    for j in range(n):
        for k in range(n):
            out[j] += an[j, k] * u[k]
    for j in range(n):
        if out[j] > effort_limit[j]:
            out[j] = effort_limit[j]
        elif out[j] < -effort_limit[j]:
            out[j] = -effort_limit[j]


@njit(cache=True, error_model="numpy")
def computed_torque_kernel(q: np.ndarray, qd: np.ndarray, u: np.ndarray, nominal: tuple,
                           effort_limit: np.ndarray) -> np.ndarray:
    """Q^u = a_N(q) u + c_N(q, qdot), eqs (9)/(16), clamped to +-effort_limit per joint."""
    out = np.empty(u.shape[0])
    _computed_torque_into(q, qd, u, nominal, effort_limit, workspace(u.shape[0]), out)
    return out


@njit(cache=True, error_model="numpy")
def _feedback_into(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, kp: np.ndarray, kd: np.ndarray, out: np.ndarray) -> None:
    for j in range(q.shape[0]):
        out[j] = u_ff[j] + kp[j] * (q_ref[j] - q[j]) + kd[j] * (qd_ref[j] - qd[j])


@njit(cache=True, error_model="numpy")
def feedback_input(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, kp: np.ndarray, kd: np.ndarray) -> np.ndarray:
    """u = u_ff + K_P e + K_D e_dot, eq (11), with e = q_d - q."""
    out = np.empty(q.shape[0])
    _feedback_into(u_ff, q_ref, qd_ref, q, qd, kp, kd, out)
    return out


@njit(cache=True, error_model="numpy")
def simulate_trial(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, kp: np.ndarray,
                   kd: np.ndarray, effort_limit: np.ndarray, period: float, substeps: int,
                   plant: tuple, nominal: tuple, mode: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One trial of the closed loop at the samples t_i = i * period, i = 0..N.

    Starts at x_d(0) (assumption (ii), eq (21)). At each sample the controller reads (q, qdot),
    forms u_i by eq (11) and the effort by eq (16); the effort is held over [t_i, t_i+1). The
    command at t_N is recorded but never applied. Returns sampled q, qdot, u and effort.
    """
    n_samples, n = u_ff.shape
    q_log = np.empty((n_samples, n))
    qd_log = np.empty((n_samples, n))
    u_log = np.empty((n_samples, n))
    effort_log = np.empty((n_samples, n))
    ws = workspace(n)
    stage = np.empty((10, n))
    extra = np.empty(2 * n)
    q = q_ref[0].copy()
    qd = qd_ref[0].copy()
    for i in range(n_samples):
        q_log[i] = q
        qd_log[i] = qd
        _feedback_into(u_ff[i], q_ref[i], qd_ref[i], q, qd, kp, kd, u_log[i])
        _computed_torque_into(q, qd, u_log[i], nominal, effort_limit, ws, effort_log[i])
        if i + 1 < n_samples:
            _rk4_period(q, qd, effort_log[i], period, substeps, plant, nominal, mode, ws, stage,
                        extra)
    return q_log, qd_log, u_log, effort_log
