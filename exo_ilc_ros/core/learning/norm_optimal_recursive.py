"""Norm-optimal ILC, (NO1)-(NO3) of :mod:`exo_ilc_ros.core.learning.norm_optimal`, without lifted
matrices.

The lifted form builds G, L = H^-1 G^T We and Phi = I - H^-1 Wu, each (n (N+1))^2 doubles
(9.8 GB per matrix for 7 joints over 5 s at 1 kHz). The same minimiser of (NO1) is the solution
of a finite-horizon linear-quadratic problem over the model's samples (Amann, Owens and Rogers
1996, the causal Riccati form; Owens 2016, ch. 9), x = (dq, dqdot) of every joint, x_0 = 0,

    x_t+1 = Abar_t x_t + B_t du_t,   Abar_t = A_t - B_t [K_P K_D],                      (R1)
    J = sum_t ||e_k(t) - C x_t||^2_We + ||du_t||^2_Wd + ||u_k(t) + du_t||^2_Wu,          (R2)

C = [I 0], u_k the previous feed-forward, du = u_k+1 - u_k. Dynamic programming with the value
V_t(x) = x^T P_t x - 2 xi_t^T x + const gives:

* the gains, backward once per model and weights (:func:`riccati_gains`), P_N = C^T We C,

      M_t = Wd + Wu + B_t^T P_t+1 B_t,   K_t = M_t^-1 B_t^T P_t+1 Abar_t,
      F_t = Abar_t - B_t K_t,   P_t = C^T We C + F_t^T P_t+1 F_t + K_t^T (Wd + Wu) K_t;   (R3)

* per update, the co-state backward from the trial's error, xi_N = C^T We e_k(N),

      v_t = M_t^-1 (B_t^T xi_t+1 - Wu u_k(t)),
      xi_t = C^T We e_k(t) + F_t^T xi_t+1 + K_t^T Wu u_k(t);                             (R4)

* and the change forward through the model (the between-trial, "nominal-model" form: the
  measured state difference of the online form replaced by the model's prediction, so the
  result is the lifted (NO2) to rounding),

      du_t = -K_t x_t + v_t,   x_t+1 = F_t x_t + B_t v_t,
      du_N = -(Wd + Wu)^-1 Wu u_k(N)   (the last sample reaches no output).             (R5)

Memory is linear in the samples (K_t, M_t^-1, F_t per sample: 14 MB for 7 joints over 5 s at
1 kHz); an update is two compiled sweeps of small matrix-vector products.

The constrained update (NO3) is the same sparse quadratic programme over z = (du, x) as
:func:`exo_ilc_ros.core.learning.norm_optimal_qp.solve_constrained`, assembled here banded
(vectorised block indices, no per-sample Python loop): :func:`solve_constrained_banded`.

This module imports of the package only the Cholesky factorisation of
:mod:`exo_ilc_ros.core.arm.dynamics` (and numpy, numba, scipy; Clarabel lazily), so any layout
can use it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.dynamics import cholesky_into

QP_TOLERANCE = 1e-12
"""Clarabel's gap and feasibility tolerances (as the lifted form's QP)."""


@njit(cache=True, error_model="numpy")
def _spd_inverse(m: np.ndarray) -> np.ndarray:
    """M^-1 of a small symmetric positive definite M (Cholesky, then two triangular solves)."""
    p = m.shape[0]
    low = np.zeros((p, p))
    if not cholesky_into(m, low):
        raise ValueError("M_t is not positive definite")
    out = np.empty((p, p))
    col = np.empty(p)
    for c in range(p):
        for i in range(p):  # L y = e_c
            s = 1.0 if i == c else 0.0
            for q in range(i):
                s -= low[i, q] * col[q]
            col[i] = s / low[i, i]
        for i in range(p - 1, -1, -1):  # L^T x = y
            s = col[i]
            for q in range(i + 1, p):
                s -= low[q, i] * col[q]
            col[i] = s / low[i, i]
        out[:, c] = col
    return 0.5 * (out + out.T)


@njit(cache=True, error_model="numpy")
def _gains_kernel(closed: np.ndarray, b: np.ndarray, error_weight: np.ndarray,
                  stage_weight: np.ndarray, gain: np.ndarray, solve: np.ndarray,
                  feedback: np.ndarray) -> None:
    """(R3) backward over t = N-1..0 into ``gain`` (K_t), ``solve`` (M_t^-1), ``feedback`` (F_t)."""
    count = closed.shape[0]
    nx, m = b.shape[1], b.shape[2]
    p = np.zeros((nx, nx))
    for j in range(m):
        p[j, j] = error_weight[j]
    for t in range(count - 2, -1, -1):
        a_t = np.ascontiguousarray(closed[t])
        b_t = np.ascontiguousarray(b[t])
        pb = p @ b_t
        mm = np.ascontiguousarray(b_t.T) @ pb
        for j in range(m):
            mm[j, j] += stage_weight[j]
        mi = _spd_inverse(0.5 * (mm + mm.T))
        k_t = mi @ (np.ascontiguousarray(pb.T) @ a_t)
        f_t = a_t - b_t @ k_t
        new = np.ascontiguousarray(f_t.T) @ (p @ f_t)
        kr = np.ascontiguousarray(k_t.T)
        for j in range(m):
            kr[:, j] *= stage_weight[j]
        new += kr @ k_t
        for j in range(m):
            new[j, j] += error_weight[j]
        p = 0.5 * (new + new.T)
        gain[t] = k_t
        solve[t] = mi
        feedback[t] = f_t


@njit(cache=True, error_model="numpy")
def _update_kernel(feedback: np.ndarray, b: np.ndarray, gain: np.ndarray, solve: np.ndarray,
                   error_weight: np.ndarray, change_weight: np.ndarray,
                   size_weight: np.ndarray, feedforward: np.ndarray, error: np.ndarray,
                   change: np.ndarray) -> None:
    """(R4) backward and (R5) forward: du into ``change`` (N+1, n)."""
    count, m = feedforward.shape
    nx = b.shape[1]
    v = np.empty((count, m))
    xi = np.zeros(nx)
    nxt = np.empty(nx)
    r = np.empty(m)
    for j in range(m):
        xi[j] = error_weight[j] * error[count - 1, j]
    for t in range(count - 2, -1, -1):
        for j in range(m):
            s = -size_weight[j] * feedforward[t, j]
            for i in range(nx):
                s += b[t, i, j] * xi[i]
            r[j] = s
        for j in range(m):
            s = 0.0
            for i in range(m):
                s += solve[t, j, i] * r[i]
            v[t, j] = s
        for i in range(nx):
            s = 0.0
            for q in range(nx):
                s += feedback[t, q, i] * xi[q]
            for j in range(m):
                s += gain[t, j, i] * size_weight[j] * feedforward[t, j]
            nxt[i] = s
        for j in range(m):
            nxt[j] += error_weight[j] * error[t, j]
        xi[:] = nxt
    x = np.zeros(nx)
    for t in range(count - 1):
        for j in range(m):
            s = v[t, j]
            for i in range(nx):
                s -= gain[t, j, i] * x[i]
            change[t, j] = s
        for i in range(nx):
            s = 0.0
            for q in range(nx):
                s += feedback[t, i, q] * x[q]
            for j in range(m):
                s += b[t, i, j] * v[t, j]
            nxt[i] = s
        x[:] = nxt
    for j in range(m):
        w = change_weight[j] + size_weight[j]
        change[count - 1, j] = (-size_weight[j] * feedforward[count - 1, j] / w) if w > 0.0 \
            else 0.0


@dataclass(frozen=True, eq=False)
class RiccatiGains:
    """The gains (R3) of one model and one set of weights; :meth:`next_feedforward` is the
    update (NO2) by (R4)-(R5), the drop-in for
    :meth:`exo_ilc_ros.core.learning.norm_optimal_model.LearningMatrices.next_feedforward`."""

    b: np.ndarray
    """(N+1, 2n, n): B_t of (R1)."""
    gain: np.ndarray
    """(N, n, 2n): K_t."""
    solve: np.ndarray
    """(N, n, n): M_t^-1."""
    feedback: np.ndarray
    """(N, 2n, 2n): F_t = Abar_t - B_t K_t."""
    error_weight: np.ndarray
    change_weight: np.ndarray
    size_weight: np.ndarray

    @property
    def joints(self) -> int:
        """n."""
        return int(self.b.shape[2])

    @property
    def samples(self) -> int:
        """N + 1."""
        return int(self.b.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes held by the gains (B_t included)."""
        return int(self.b.nbytes + self.gain.nbytes + self.solve.nbytes + self.feedback.nbytes)

    def change(self, feedforward: np.ndarray, error: np.ndarray) -> np.ndarray:
        """du = u_ff,k+1 - u_ff,k, shape (N+1, n), from u_ff,k and e_k (either (N+1, n) or
        stacked sample by sample)."""
        shape = (self.samples, self.joints)
        u = np.ascontiguousarray(np.reshape(feedforward, shape), dtype=np.float64)
        e = np.ascontiguousarray(np.reshape(error, shape), dtype=np.float64)
        out = np.empty(shape)
        _update_kernel(self.feedback, self.b, self.gain, self.solve, self.error_weight,
                       self.change_weight, self.size_weight, u, e, out)
        return out

    def next_feedforward(self, feedforward: np.ndarray, error: np.ndarray) -> np.ndarray:
        """u_ff,k+1 of (NO2), in the shape of ``feedforward`` (stacked as the lifted form's, or
        (N+1, n))."""
        u = np.asarray(feedforward, dtype=np.float64)
        return np.asarray(u + self.change(u, error).reshape(u.shape))


def riccati_gains(a: np.ndarray, b: np.ndarray, k: np.ndarray, error_weight: np.ndarray,
                  change_weight: np.ndarray, size_weight: np.ndarray) -> RiccatiGains:
    """(R3) for the model x_t+1 = A_t x_t + B_t (u_ff + K_P e + K_D e_dot) of
    :class:`exo_ilc_ros.core.learning.norm_optimal_model.LiftedModel` (``a`` (N+1, 2n, 2n),
    ``b`` (N+1, 2n, n), ``k`` = [K_P K_D]) and the per-joint weights We, Wd, Wu of (NO1)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    count, nx, m = b.shape
    if a.shape != (count, nx, nx) or np.shape(k) != (m, nx) or nx != 2 * m:
        raise ValueError(f"model shapes {a.shape}, {b.shape}, {np.shape(k)} do not fit "
                         "(N+1, 2n, 2n), (N+1, 2n, n), (n, 2n)")
    we, wd, wu = (np.ascontiguousarray(w, dtype=np.float64) for w in
                  (error_weight, change_weight, size_weight))
    if np.any(wd + wu <= 0.0):
        raise ValueError("the input-change plus input-size weight must be > 0 for every joint "
                         "(the last sample's input reaches no output; the lifted H is singular "
                         "too)")
    closed = np.ascontiguousarray(a - b @ np.asarray(k, dtype=np.float64))
    steps = max(count - 1, 0)
    gain = np.zeros((steps, m, nx))
    solve = np.zeros((steps, m, m))
    feedback = np.zeros((steps, nx, nx))
    _gains_kernel(closed, b, we, wd + wu, gain, solve, feedback)
    return RiccatiGains(b, gain, solve, feedback, we, wd, wu)


def lifted_gradient(gains: RiccatiGains, error: np.ndarray) -> np.ndarray:
    """G^T We e without G: one co-state sweep with K = 0, (G^T We e)_t = B_t^T xi_t+1,
    xi_t = C^T We e(t) + Abar_t^T xi_t+1 (used by the tests as an adjoint check; the closed
    loop Abar_t is F_t + B_t K_t)."""
    count, m = gains.samples, gains.joints
    e = np.reshape(np.asarray(error, dtype=np.float64), (count, m))
    closed = gains.feedback + gains.b[:-1] @ gains.gain
    out = np.zeros((count, m))
    xi = np.zeros(2 * m)
    xi[:m] = gains.error_weight * e[-1]
    for t in range(count - 2, -1, -1):
        out[t] = gains.b[t].T @ xi
        xi = closed[t].T @ xi
        xi[:m] += gains.error_weight * e[t]
    return out


# --- the constrained update (NO3), banded ------------------------------------------------------

@dataclass(frozen=True)
class BandedStep:
    """The solution of (NO3): the fields of
    :class:`exo_ilc_ros.core.learning.norm_optimal_qp.ConstrainedStep`, and whether Clarabel
    solved it."""

    change: np.ndarray
    """u_ff,k+1 - u_ff,k, shape (N+1, joints)."""
    predicted_effort: np.ndarray
    effort_active: np.ndarray
    """Per joint: samples at the effort limit in the prediction."""
    feedforward_active: np.ndarray
    """Per joint: samples at the feed-forward bound."""
    status: str
    solved: bool


def _blocks(row0: np.ndarray, col0: np.ndarray, mats: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """COO triplets of the dense blocks ``mats[i]`` placed at (row0[i], col0[i])."""
    _, p, q = mats.shape
    rows = np.broadcast_to(row0[:, None, None] + np.arange(p)[None, :, None], mats.shape)
    cols = np.broadcast_to(col0[:, None, None] + np.arange(q)[None, None, :], mats.shape)
    return rows.ravel(), cols.ravel(), mats.ravel()


def solve_constrained_banded(a: np.ndarray, b: np.ndarray, k: np.ndarray,
                             error_weight: np.ndarray, change_weight: np.ndarray,
                             size_weight: np.ndarray, feedforward: np.ndarray,
                             error: np.ndarray, effort: np.ndarray, inertia: np.ndarray,
                             effort_jacobian: np.ndarray, effort_limit: np.ndarray,
                             feedforward_limit: np.ndarray) -> BandedStep:
    """(NO3) as the sparse QP over z = (du_0..du_N, x_0..x_N) with the model (R1) as equalities
    and the predicted effort tau_k + a_N(q_k)(du - K x) + J_k x within +-``effort_limit`` (the
    margin already applied), abs(u_ff + du) <= ``feedforward_limit`` (inf: none); ``effort``,
    ``inertia``, ``effort_jacobian`` are tau_k, a_N(q_k) and d tau / d x along trial k, as
    ``norm_optimal_qp._effort_along`` gives them. The matrix is the lifted form's, entry for entry,
    assembled from vectorised block indices. Over 10 parameters because it takes the QP's data
    as plain arrays, not the law's matrices, constraints and record, so this module imports
    nothing of the package but the Cholesky factorisation (module docstring)."""
    import clarabel
    from scipy import sparse

    u_ff = np.asarray(feedforward, dtype=float)
    count, n = u_ff.shape
    nx = 2 * n
    nv = count * n
    we, wd, wu = (np.tile(np.asarray(w, dtype=float), count)
                  for w in (error_weight, change_weight, size_weight))
    e = np.asarray(error, dtype=float)
    px = np.zeros((count, nx))
    px[:, :n] = 2.0 * we.reshape(count, n)
    qx = np.zeros((count, nx))
    qx[:, :n] = -2.0 * we.reshape(count, n) * e
    p = sparse.diags(np.concatenate([2.0 * (wd + wu), px.ravel()])).tocsc()
    q = np.concatenate([2.0 * wu * u_ff.ravel(), qx.ravel()])
    k = np.asarray(k, dtype=float)
    closed = np.asarray(a, dtype=float) - np.asarray(b, dtype=float) @ k
    steps = np.arange(count - 1)
    x_col = nv + np.arange(count) * nx
    eye = np.broadcast_to(np.eye(nx), (count, nx, nx))
    parts = [_blocks(np.arange(count) * nx, x_col, eye),  # x_0 = 0, x_i+1 - ...
             _blocks((steps + 1) * nx, x_col[steps], -closed[:-1]),
             _blocks((steps + 1) * nx, steps * n, -np.asarray(b, dtype=float)[:-1])]
    equalities = count * nx
    lim = np.asarray(effort_limit, dtype=float)
    inertia = np.asarray(inertia, dtype=float)
    state_effort = np.asarray(effort_jacobian, dtype=float) - inertia @ k
    tau = np.asarray(effort, dtype=float)
    bounds = []
    row = equalities
    for sign in (1.0, -1.0):
        r0 = row + np.arange(count) * n
        parts.append(_blocks(r0, np.arange(count) * n, sign * inertia))
        parts.append(_blocks(r0, x_col, sign * state_effort))
        row += count * n
        bounds.append((lim - sign * tau).ravel())
    ff_all = np.tile(np.asarray(feedforward_limit, dtype=float), count)
    bounded = np.flatnonzero(np.isfinite(ff_all))
    if bounded.size:
        for sign in (1.0, -1.0):
            parts.append((row + np.arange(bounded.size), bounded, np.full(bounded.size, sign)))
            row += bounded.size
            bounds.append(ff_all[bounded] - sign * u_ff.ravel()[bounded])
    rows, cols, vals = (np.concatenate([part[i] for part in parts]) for i in range(3))
    matrix = sparse.csc_matrix((vals, (rows, cols)), shape=(row, nv + count * nx))
    rhs = np.concatenate([np.zeros(equalities), *bounds])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = QP_TOLERANCE
    settings.tol_ktratio = 1e-10
    solver = clarabel.DefaultSolver(p, q, matrix, rhs,
                                    [clarabel.ZeroConeT(equalities),
                                     clarabel.NonnegativeConeT(row - equalities)], settings)
    solution = solver.solve()
    status = str(solution.status)
    z = np.asarray(solution.x)
    du = z[:nv].reshape(count, n)
    x = z[nv:].reshape(count, nx)
    predicted = (tau + np.einsum("ijk,ik->ij", inertia, du - x @ k.T)
                 + np.einsum("ijk,ik->ij", np.asarray(effort_jacobian, dtype=float), x))
    tol = 1e-6
    effort_active = np.sum(np.abs(predicted) >= lim * (1.0 - tol), axis=0)
    new = u_ff + du
    ff_active = np.sum(np.abs(new) >= np.asarray(feedforward_limit, dtype=float) * (1.0 - tol),
                       axis=0)
    return BandedStep(du, predicted, effort_active, ff_active, status, "Solved" in status)
