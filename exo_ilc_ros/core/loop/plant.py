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
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.dynamics import forward_dynamics_into, inertia_and_bias_into, workspace
from ..arm.joint_forces import passive_effort_into

if TYPE_CHECKING:
    pass


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
def finite_state(q: np.ndarray, qd: np.ndarray) -> bool:
    """True if every q_j and qdot_j is finite: False means the plant diverged
    (:mod:`.divergence`)."""
    for j in range(q.shape[0]):  # noqa: SIM110  (a loop numba compiles)
        if not (np.isfinite(q[j]) and np.isfinite(qd[j])):
            return False
    return True


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
def plant_period_with_joint_forces(effort: np.ndarray, limit: np.ndarray,
                                   saturated: np.ndarray, q: np.ndarray, qd: np.ndarray,
                                   applied: np.ndarray, period: float, substeps: int,
                                   plant: tuple, nominal: tuple, mode: int, ws: tuple,
                                   stage: np.ndarray, extra: np.ndarray, joint: np.ndarray,
                                   inverse_stribeck: float, total: np.ndarray) -> int:
    """:func:`plant_period` with the passive joint forces of ``joint`` at every RK4 stage
    (:func:`rk4_period_with_joint_forces`; a URDF arm's own damping and friction between
    trials). Returns the number of joints beyond the limit (-1: a non-finite effort refused)."""
    beyond = clamp_counted(effort, limit, saturated, applied)
    if beyond >= 0:
        rk4_period_with_joint_forces(q, qd, applied, period, substeps, plant, nominal, mode, ws,
                                     stage, extra, True, joint, inverse_stribeck, total)
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


