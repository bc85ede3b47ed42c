"""The constrained norm-optimal update, eq (NO3) of :mod:`.norm_optimal`: the same minimiser
subject to the next trial's predicted effort within the effort limit and the feed-forward within
its bound, as a QP in the model's states (Clarabel), dense (:func:`solve_constrained`, the
oracle) or assembled banded (:func:`solve_constrained_recursive`, what the law uses)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.dynamics import inertia_and_bias
from ..errors import SafetyError
from ..loop.record import TrialRecord
from .norm_optimal_model import LearningMatrices, RecursiveMatrices
from .norm_optimal_recursive import solve_constrained_banded


@dataclass(frozen=True, eq=False)
class Constraints:
    """What (NO3) bounds: the effort limit (N m) and the feed-forward bound (inf: none), with
    the nominal arm that predicts the effort."""

    effort_limit: np.ndarray
    feedforward_limit: np.ndarray
    nominal: tuple[np.ndarray, ...]
    effort_margin: float = 0.0
    """Share of the effort limit kept free for the prediction's error."""


def _effort_along(record: TrialRecord, nominal: tuple[np.ndarray, ...], step: float = 1e-6
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along trial k: tau_k = a_N(q) u + c_N(q, qdot) (before the limit clamps it), a_N(q) and
    d tau / d (q, qdot) at fixed u (central differences: gravity and Coriolis change with the
    state the next trial reaches)."""
    count, n = record.position.shape
    tau = np.empty((count, n))
    inertia = np.empty((count, n, n))
    jacobian = np.empty((count, n, 2 * n))
    _effort_along_kernel(np.ascontiguousarray(record.position),
                         np.ascontiguousarray(record.velocity),
                         np.ascontiguousarray(record.control_input), step, nominal, tau,
                         inertia, jacobian)
    return tau, inertia, jacobian


@njit(cache=True, error_model="numpy")
def _effort_along_kernel(position: np.ndarray, velocity: np.ndarray, control: np.ndarray,
                         step: float, nominal: tuple, tau: np.ndarray, inertia: np.ndarray,
                         jacobian: np.ndarray) -> None:
    """:func:`_effort_along` compiled (the same doubles as its former Python loop);
    ``nominal``: the arm's ``kernel_args``."""
    count, n = position.shape
    for i in range(count):
        u = control[i].copy()
        a, c = inertia_and_bias(position[i].copy(), velocity[i].copy(), *nominal)
        inertia[i] = a
        tau[i] = a @ u + c
        x = np.concatenate((position[i], velocity[i]))
        for m in range(2 * n):
            x_plus, x_minus = x.copy(), x.copy()
            x_plus[m] += step
            x_minus[m] -= step
            a, c = inertia_and_bias(x_plus[:n].copy(), x_plus[n:].copy(), *nominal)
            e_plus = a @ u + c
            a, c = inertia_and_bias(x_minus[:n].copy(), x_minus[n:].copy(), *nominal)
            e_minus = a @ u + c
            for k in range(n):
                jacobian[i, k, m] = (e_plus[k] - e_minus[k]) / (2.0 * step)


@dataclass(frozen=True)
class ConstrainedStep:
    """The solution of (NO3) and which constraints hold with equality."""

    change: np.ndarray
    """u_ff,k+1 - u_ff,k, shape (N+1, joints)."""
    predicted_effort: np.ndarray
    effort_active: np.ndarray
    """Per joint: samples at the effort limit in the prediction."""
    feedforward_active: np.ndarray
    """Per joint: samples at the feed-forward bound."""
    status: str


QP_TOLERANCE = 1e-12
"""Clarabel's gap and feasibility tolerances: the QP's u_ff within ~1e-8 of (NO2)'s when no
constraint is active (tested)."""


def solve_constrained(matrices: LearningMatrices | RecursiveMatrices, constraints: Constraints,
                      record: TrialRecord) -> ConstrainedStep:
    """(NO3) as a sparse QP over z = (du_ff, x_0..x_N) with the model's dynamics as equalities,
    solved by Clarabel (interior point). Active: within 1e-6 (relative) of a bound."""
    from scipy import sparse

    model, w = matrices.model, matrices.weights
    count, n = record.error.shape
    nv = count * n
    we, wd, wu = w.stacked(count)
    u_ff = record.feedforward.ravel()
    # cost 1/2 z' P z + q' z: sum we (e - dq)^2 + wd du^2 + wu (u_ff + du)^2 (constants dropped)
    px = np.zeros((count, 2 * n))
    px[:, :n] = 2.0 * we.reshape(count, n)
    qx = np.zeros((count, 2 * n))
    qx[:, :n] = -2.0 * we.reshape(count, n) * record.error
    p = sparse.diags(np.concatenate([2.0 * (wd + wu), px.ravel()])).tocsc()
    q = np.concatenate([2.0 * wu * u_ff, qx.ravel()])
    tau, inertia, jacobian = _effort_along(record, constraints.nominal)
    lim = constraints.effort_limit * (1.0 - constraints.effort_margin)
    a, b, equalities = _constraint_rows(model.a, model.b, model.k, u_ff, tau, inertia, jacobian,
                                        lim, constraints.feedforward_limit)
    z, status = _clarabel(p, q, a, b, equalities, record.trial)
    du = z[:nv].reshape(count, n)
    x = z[nv:].reshape(count, 2 * n)
    predicted = (tau + np.einsum("ijk,ik->ij", inertia, du - x @ model.k.T)
                 + np.einsum("ijk,ik->ij", jacobian, x))
    tol = 1e-6
    effort_active = np.sum(np.abs(predicted) >= lim * (1.0 - tol), axis=0)
    new = record.feedforward + du
    ff_active = np.sum(np.abs(new) >= constraints.feedforward_limit * (1.0 - tol), axis=0)
    return ConstrainedStep(du, predicted, effort_active, ff_active, status)


def _constraint_rows(a_model: np.ndarray, b_model: np.ndarray, k: np.ndarray,
                     u_ff: np.ndarray, tau: np.ndarray, inertia: np.ndarray,
                     jacobian: np.ndarray, lim: np.ndarray, feedforward_limit: np.ndarray
                     ) -> tuple[Any, np.ndarray, int]:
    """The QP's constraint matrix A (sparse), right-hand side b and number of equality rows:
    the model's dynamics x_i+1 = (A_i - B_i K) x_i + B_i du_i from x_0 = 0, then the effort
    bounds of (NO3) and the feed-forward bound."""
    from scipy import sparse

    count, n = tau.shape
    nv = count * n
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    row = 0

    def x_col(i: int) -> int:
        return nv + i * 2 * n

    def block(r0: int, c0: int, m: np.ndarray) -> None:
        rr, cc = np.nonzero(np.ones_like(m, dtype=bool))
        rows.append(rr + r0)
        cols.append(cc + c0)
        vals.append(m.ravel())

    # equalities: x_0 = 0; x_i+1 - (A_i - B_i K) x_i - B_i du_i = 0
    block(row, x_col(0), np.eye(2 * n))
    row += 2 * n
    closed = a_model - b_model @ k
    for i in range(count - 1):
        block(row, x_col(i + 1), np.eye(2 * n))
        block(row, x_col(i), -closed[i])
        block(row, i * n, -b_model[i])
        row += 2 * n
    equalities = row
    bounds: list[np.ndarray] = []
    # effort: +-(a_N,i (du_i - K x_i) + J_i x_i) <= lim -+ tau_i
    for sign in (1.0, -1.0):
        for i in range(count):
            block(row, i * n, sign * inertia[i])
            block(row, x_col(i), sign * (jacobian[i] - inertia[i] @ k))
            row += n
        bounds.append((lim - sign * tau).ravel())
    bounded = np.flatnonzero(np.isfinite(np.tile(feedforward_limit, count)))
    if bounded.size:
        ff_lim = np.tile(feedforward_limit, count)[bounded]
        for sign in (1.0, -1.0):
            rows.append(row + np.arange(bounded.size))
            cols.append(bounded)
            vals.append(np.full(bounded.size, sign))
            row += bounded.size
            bounds.append(ff_lim - sign * u_ff[bounded])
    a = sparse.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(row, nv + count * 2 * n))
    return a, np.concatenate([np.zeros(equalities), *bounds]), equalities


def _clarabel(p: Any, q: np.ndarray, a: Any, b: np.ndarray, equalities: int,
              trial: int) -> tuple[np.ndarray, str]:
    """The QP min 1/2 z' P z + q' z, A z + s = b, s in {0}^equalities x R+^rest, by Clarabel:
    its solution and status (an error if not solved)."""
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    # Tight: the input-change weight is tiny, so the cost is flat along the directions the
    # model barely sees; the default 1e-8 gap leaves ~1e-4 rad/s^2 of slack in u_ff there.
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = QP_TOLERANCE
    settings.tol_ktratio = 1e-10
    cones = [clarabel.ZeroConeT(equalities), clarabel.NonnegativeConeT(a.shape[0] - equalities)]
    solver = clarabel.DefaultSolver(p, q, a, b, cones, settings)
    solution = solver.solve()
    status = str(solution.status)
    if "Solved" not in status:
        raise SafetyError(f"trial {trial}: the constrained norm-optimal update was not "
                          f"solved ({status}); the limits may be infeasible together")
    return np.asarray(solution.x), status


def solve_constrained_recursive(matrices: RecursiveMatrices, constraints: Constraints,
                                record: TrialRecord) -> ConstrainedStep:
    """(NO3) as :func:`solve_constrained`, the QP assembled banded
    (:func:`exo_ilc_ros.core.learning.norm_optimal_recursive.solve_constrained_banded`)."""
    model, w = matrices.model, matrices.weights
    tau, inertia, jacobian = _effort_along(record, constraints.nominal)
    banded = solve_constrained_banded(
        model.a, model.b, model.k, w.error, w.input_change, w.input_size, record.feedforward,
        record.error, tau, inertia, jacobian,
        constraints.effort_limit * (1.0 - constraints.effort_margin),
        constraints.feedforward_limit)
    if not banded.solved:
        raise SafetyError(f"trial {record.trial}: the constrained norm-optimal update was not "
                          f"solved ({banded.status}); the limits may be infeasible together")
    return ConstrainedStep(banded.change, banded.predicted_effort, banded.effort_active,
                           banded.feedforward_active, banded.status)


def constraint_notes(step: ConstrainedStep) -> tuple[str, ...]:
    """One line per kind of active constraint of (NO3) (empty: none active)."""
    notes = []
    if np.any(step.effort_active):
        notes.append("effort limit active at " + "/".join(str(int(c)) for c in step.effort_active)
                     + " samples (per joint) of the next trial's predicted effort")
    if np.any(step.feedforward_active):
        notes.append("feed-forward bound active at "
                     + "/".join(str(int(c)) for c in step.feedforward_active)
                     + " samples (per joint)")
    return tuple(notes)
