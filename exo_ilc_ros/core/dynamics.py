"""Compiled kernels of the Rodriguez approach, eqs (1)-(7), for an open chain of revolute joints.

The chain is described by arrays (so numba can compile it): for link i, ``axes[i]`` is the joint
axis and ``offsets[i]`` the joint origin, both in the frame of link i-1 (all frames are parallel to
the inertial frame Oxyz at q = 0), ``coms[i]`` the centre of mass in link i's frame relative to
its joint, ``inertias[i]`` the central inertia tensor in link i's frame, ``masses[i]`` the mass.
``gravity`` is the gravity acceleration vector in Oxyz (0, 0, -g).

The hot kernels write into a :func:`workspace` allocated once per integration call, so the RK4
loop allocates nothing; the allocating wrappers used by ``model.py`` call the same kernels.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, error_model="numpy")
def _cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True, error_model="numpy")
def _matvec(m: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    for r in range(3):
        out[r] = m[r, 0] * v[0] + m[r, 1] * v[1] + m[r, 2] * v[2]


@njit(cache=True, error_model="numpy")
def _matmul(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    for r in range(3):
        for c in range(3):
            out[r, c] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]


@njit(cache=True, error_model="numpy")
def _rotation(axis: np.ndarray, angle: float, out: np.ndarray) -> None:
    """Rotation by ``angle`` about the unit vector ``axis`` (Rodrigues' formula)."""
    c = np.cos(angle)
    s = np.sin(angle)
    v = 1.0 - c
    x, y, z = axis[0], axis[1], axis[2]
    out[0, 0] = c + x * x * v
    out[0, 1] = x * y * v - z * s
    out[0, 2] = x * z * v + y * s
    out[1, 0] = y * x * v + z * s
    out[1, 1] = c + y * y * v
    out[1, 2] = y * z * v - x * s
    out[2, 0] = z * x * v - y * s
    out[2, 1] = z * y * v + x * s
    out[2, 2] = c + z * z * v


@njit(cache=True, error_model="numpy")
def workspace(n: int) -> tuple:
    """Scratch arrays for the kernels of an ``n``-joint chain (allocated once, reused)."""
    return (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3)),  # frames
            np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)),  # rotations
            np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(n),  # vectors
            np.empty((n, 3)), np.empty((n, n, 3)), np.empty((n, n, 3)), np.empty((n, 3)),  # T, dT
            np.empty((n, n)), np.empty((n, n, n)), np.empty(n),  # a, da, qg
            np.empty((n, n)), np.empty(n))  # Cholesky factor, forward substitution


@njit(cache=True, error_model="numpy")
def _frames_into(q: np.ndarray, axes: np.ndarray, offsets: np.ndarray, coms: np.ndarray,
                 inertias: np.ndarray, ws: tuple) -> None:
    e, p, rc, jw, rot, nxt, step, tmp, v, pos = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], \
        ws[6], ws[7], ws[8], ws[9]
    n = q.shape[0]
    for r in range(3):
        pos[r] = 0.0
        for c in range(3):
            rot[r, c] = 1.0 if r == c else 0.0
    for i in range(n):
        _matvec(rot, offsets[i], v)
        for c in range(3):
            pos[c] += v[c]
            p[i, c] = pos[c]
        _matvec(rot, axes[i], e[i])
        _rotation(axes[i], q[i], step)
        _matmul(rot, step, nxt)
        rot[:, :] = nxt
        _matvec(rot, coms[i], v)
        for c in range(3):
            rc[i, c] = pos[c] + v[c]
        _matmul(rot, inertias[i], tmp)
        for r in range(3):
            for c in range(3):
                jw[i, r, c] = tmp[r, 0] * rot[c, 0] + tmp[r, 1] * rot[c, 1] + tmp[r, 2] * rot[c, 2]


@njit(cache=True, error_model="numpy")
def _metric_into(q: np.ndarray, masses: np.ndarray, axes: np.ndarray, offsets: np.ndarray,
                 coms: np.ndarray, inertias: np.ndarray, gravity: np.ndarray,
                 with_derivative: bool, ws: tuple) -> None:
    """Fill ws's a(q), da/dq and Q^g: see :func:`metric_terms`."""
    _frames_into(q, axes, offsets, coms, inertias, ws)
    e, p, rc, jw = ws[0], ws[1], ws[2], ws[3]
    lever, dlever, tmp, tmp2 = ws[8], ws[9], ws[10], ws[11]
    t, dt, de, je = ws[13], ws[14], ws[15], ws[16]
    a, da, qg = ws[17], ws[18], ws[19]
    n = q.shape[0]
    a[:, :] = 0.0
    qg[:] = 0.0
    if with_derivative:
        da[:, :, :] = 0.0
        de[:, :, :] = 0.0
        for k in range(n):
            for al in range(k + 1, n):
                _cross(e[k], e[al], de[k, al])
    for i in range(n):
        mi = masses[i]
        for al in range(i + 1):
            for c in range(3):
                lever[c] = rc[i, c] - p[al, c]
            _cross(e[al], lever, t[al])
            _matvec(jw[i], e[al], je[al])
            if with_derivative:
                for k in range(i + 1):
                    if k <= al:
                        _cross(e[k], lever, dlever)
                    else:
                        for c in range(3):
                            tmp[c] = rc[i, c] - p[k, c]
                        _cross(e[k], tmp, dlever)
                    _cross(de[k, al], lever, tmp)
                    _cross(e[al], dlever, tmp2)
                    for c in range(3):
                        dt[k, al, c] = tmp[c] + tmp2[c]
        for al in range(i + 1):
            qg[al] += mi * _dot(gravity, t[al])
            for be in range(i + 1):
                a[al, be] += mi * _dot(t[al], t[be]) + _dot(e[al], je[be])
                if with_derivative:
                    for k in range(i + 1):
                        # rotational part: d(e_a^T J e_b) with dJ = [e_k]x J - J [e_k]x
                        _cross(e[k], je[be], tmp)
                        _cross(e[k], e[be], tmp2)
                        rot = (_dot(de[k, al], je[be]) + _dot(je[al], de[k, be])
                               + _dot(e[al], tmp) - _dot(je[al], tmp2))
                        da[k, al, be] += mi * (_dot(dt[k, al], t[be])
                                               + _dot(t[al], dt[k, be])) + rot
    for al in range(n):
        for be in range(al + 1, n):
            a[al, be] = a[be, al]


@njit(cache=True, error_model="numpy")
def metric_terms(q: np.ndarray, masses: np.ndarray, axes: np.ndarray, offsets: np.ndarray,
                 coms: np.ndarray, inertias: np.ndarray, gravity: np.ndarray,
                 with_derivative: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Metric tensor a(q), its derivatives and the gravity forces Q^g, eqs (2)-(4), (6).

    Quasi-base vectors, eqs (3)-(4), for revolute joints: T_a(i) = e_a x (r_Ci - p_a) and
    Omega_a(i) = e_a for a <= i, zero otherwise. Eq (2): a_ab = sum_i m_i T_a(i).T_b(i)
    + Omega_a(i)^T J_Ci Omega_b(i). Gravity, eq (6): Q^g_c = sum_i m_i g . T_c(i).
    Returns ``(a, da, qg)`` with ``da[k, a, b] = d a_ab / d q_k`` (zeros unless
    ``with_derivative``), obtained analytically from d e_a / d q_k = e_k x e_a (k < a) and
    d r / d q_k = e_k x (r - p_k) for the points moved by joint k.
    """
    ws = workspace(q.shape[0])
    ws[18][:, :, :] = 0.0
    _metric_into(q, masses, axes, offsets, coms, inertias, gravity, with_derivative, ws)
    return ws[17].copy(), ws[18].copy(), ws[19].copy()


@njit(cache=True, error_model="numpy")
def chain_frames(q: np.ndarray, axes: np.ndarray, offsets: np.ndarray, coms: np.ndarray,
                 inertias: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Joint axes e_i, joint origins p_i, centres of mass r_Ci and inertia tensors in Oxyz."""
    ws = workspace(q.shape[0])
    _frames_into(q, axes, offsets, coms, inertias, ws)
    return ws[0].copy(), ws[1].copy(), ws[2].copy(), ws[3].copy()


@njit(cache=True, error_model="numpy")
def christoffel_from_derivative(da: np.ndarray) -> np.ndarray:
    """Christoffel symbols of the first kind, eq (5): G[a, b, c] = Gamma_{ab,c}."""
    n = da.shape[0]
    g = np.empty((n, n, n))
    for al in range(n):
        for be in range(n):
            for ga in range(n):
                g[al, be, ga] = 0.5 * (da[al, be, ga] + da[be, ga, al] - da[ga, al, be])
    return g


@njit(cache=True, error_model="numpy")
def christoffel_bias(da: np.ndarray, qg: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """c(q, qdot) from eq (5): sum_ab Gamma_{ab,c} qdot_a qdot_b - Q^g_c (reference path)."""
    n = qd.shape[0]
    out = np.empty(n)
    for ga in range(n):
        s = 0.0
        for al in range(n):
            for be in range(n):
                s += 0.5 * (da[al, be, ga] + da[be, ga, al] - da[ga, al, be]) * qd[al] * qd[be]
        out[ga] = s - qg[ga]
    return out


@njit(cache=True, error_model="numpy")
def _solve_spd_into(a: np.ndarray, b: np.ndarray, low: np.ndarray, y: np.ndarray,
                    x: np.ndarray) -> None:
    n = b.shape[0]
    for i in range(n):
        for j in range(i + 1):
            s = a[i, j]
            for k in range(j):
                s -= low[i, k] * low[j, k]
            if i == j:
                if s <= 0.0:
                    raise ValueError("metric tensor is not positive definite")
                low[i, i] = np.sqrt(s)
            else:
                low[i, j] = s / low[j, j]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= low[i, k] * y[k]
        y[i] = s / low[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= low[k, i] * x[k]
        x[i] = s / low[i, i]


@njit(cache=True, error_model="numpy")
def solve_spd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve a x = b for a symmetric positive definite ``a`` (Cholesky)."""
    n = b.shape[0]
    x = np.empty(n)
    _solve_spd_into(a, b, np.empty((n, n)), np.empty(n), x)
    return x


@njit(cache=True, error_model="numpy")
def _row(a: np.ndarray, i: int) -> tuple[float, float, float]:
    return (a[i, 0], a[i, 1], a[i, 2])


@njit(cache=True, error_model="numpy")
def _tcross(a: tuple[float, float, float],
            b: tuple[float, float, float]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, error_model="numpy")
def _tdot(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, error_model="numpy")
def _tmat(m: np.ndarray, i: int, v: tuple[float, float, float]) -> tuple[float, float, float]:
    return (m[i, 0, 0] * v[0] + m[i, 0, 1] * v[1] + m[i, 0, 2] * v[2],
            m[i, 1, 0] * v[0] + m[i, 1, 1] * v[1] + m[i, 1, 2] * v[2],
            m[i, 2, 0] * v[0] + m[i, 2, 1] * v[1] + m[i, 2, 2] * v[2])


@njit(cache=True, error_model="numpy")
def inertia_and_bias_into(q: np.ndarray, qd: np.ndarray, masses: np.ndarray, axes: np.ndarray,
                          offsets: np.ndarray, coms: np.ndarray, inertias: np.ndarray,
                          gravity: np.ndarray, ws: tuple, bias: np.ndarray) -> np.ndarray:
    """Fill ``bias`` with c(q, qdot) of eq (7); return a(q) (an array of ``ws``).

    a(q) by eq (2) from the quasi-base vectors T_a(i) = e_a x (r_Ci - p_a), Omega_a(i) = e_a,
    eqs (3)-(4). c is evaluated without forming Gamma: sum_ab Gamma_{ab,c} qdot_a qdot_b equals
    the projection onto the quasi-base vectors of the velocity-product accelerations,
    sum_i T_c(i) . m_i b_i + Omega_c(i) . (J_i dw_i + w_i x J_i w_i), with b_i the centre of
    mass acceleration and dw_i the angular acceleration at qdd = 0, computed outward along the
    chain in O(n) (tested equal to the eq (5) contraction). Gravity enters as -Q^g, eq (6).
    """
    _frames_into(q, axes, offsets, coms, inertias, ws)
    e, p, rc, jw = ws[0], ws[1], ws[2], ws[3]
    a = ws[17]
    n = q.shape[0]
    g = _row(gravity.reshape(1, 3), 0)
    for al in range(n):
        bias[al] = 0.0
        for be in range(n):
            a[al, be] = 0.0
    w = (0.0, 0.0, 0.0)  # angular velocity of link i-1, then i
    wb = (0.0, 0.0, 0.0)  # its angular acceleration at qdd = 0
    pb = (0.0, 0.0, 0.0)  # acceleration of joint origin p_i at qdd = 0
    for i in range(n):
        pi = _row(p, i)
        if i > 0:
            prev = _row(p, i - 1)
            d = (pi[0] - prev[0], pi[1] - prev[1], pi[2] - prev[2])
            x1 = _tcross(wb, d)
            x2 = _tcross(w, _tcross(w, d))
            pb = (pb[0] + x1[0] + x2[0], pb[1] + x1[1] + x2[1], pb[2] + x1[2] + x2[2])
        ei = _row(e, i)
        de = _tcross(w, ei)  # d e_i / dt = w_{i-1} x e_i
        s = qd[i]
        wb = (wb[0] + de[0] * s, wb[1] + de[1] * s, wb[2] + de[2] * s)
        w = (w[0] + ei[0] * s, w[1] + ei[1] * s, w[2] + ei[2] * s)
        ci = _row(rc, i)
        d = (ci[0] - pi[0], ci[1] - pi[1], ci[2] - pi[2])
        x1 = _tcross(wb, d)
        x2 = _tcross(w, _tcross(w, d))
        mi = masses[i]
        f = (mi * (pb[0] + x1[0] + x2[0] - g[0]), mi * (pb[1] + x1[1] + x2[1] - g[1]),
             mi * (pb[2] + x1[2] + x2[2] - g[2]))
        jww = _tmat(jw, i, w)
        x1 = _tcross(w, jww)
        x2 = _tmat(jw, i, wb)
        tau = (x1[0] + x2[0], x1[1] + x2[1], x1[2] + x2[2])
        for al in range(i + 1):
            ea = _row(e, al)
            pa = _row(p, al)
            ta = _tcross(ea, (ci[0] - pa[0], ci[1] - pa[1], ci[2] - pa[2]))
            jea = _tmat(jw, i, ea)
            bias[al] += _tdot(ta, f) + _tdot(ea, tau)
            for be in range(al + 1):
                eb = _row(e, be)
                pbe = _row(p, be)
                tb = _tcross(eb, (ci[0] - pbe[0], ci[1] - pbe[1], ci[2] - pbe[2]))
                a[al, be] += mi * _tdot(ta, tb) + _tdot(jea, eb)
    for al in range(n):
        for be in range(al + 1, n):
            a[al, be] = a[be, al]
    return a


@njit(cache=True, error_model="numpy")
def inertia_and_bias(q: np.ndarray, qd: np.ndarray, masses: np.ndarray, axes: np.ndarray,
                     offsets: np.ndarray, coms: np.ndarray, inertias: np.ndarray,
                     gravity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a(q) and c(q, qdot) of eq (7): c = sum_ab Gamma_{ab,c} qdot_a qdot_b - Q^g_c."""
    n = q.shape[0]
    ws = workspace(n)
    bias = np.empty(n)
    a = inertia_and_bias_into(q, qd, masses, axes, offsets, coms, inertias, gravity, ws, bias)
    return a.copy(), bias


@njit(cache=True, error_model="numpy")
def forward_dynamics_into(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, masses: np.ndarray,
                          axes: np.ndarray, offsets: np.ndarray, coms: np.ndarray,
                          inertias: np.ndarray, gravity: np.ndarray, ws: tuple,
                          out: np.ndarray) -> None:
    """qdd of eq (8), a(q) qdd = Q - c(q, qdot), written into ``out``."""
    bias = ws[12]
    a = inertia_and_bias_into(q, qd, masses, axes, offsets, coms, inertias, gravity, ws, bias)
    for j in range(q.shape[0]):
        bias[j] = effort[j] - bias[j]
    _solve_spd_into(a, bias, ws[20], ws[21], out)
