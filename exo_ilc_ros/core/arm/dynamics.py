"""Compiled kernels of the Rodriguez approach, eqs (1)-(7), for an open chain of revolute joints.

The chain is described by arrays (so numba can compile it): for link i, ``axes[i]`` is the joint
axis and ``offsets[i]`` the joint origin, both in the frame of link i-1 (all frames are parallel to
the inertial frame Oxyz at q = 0), ``coms[i]`` the centre of mass in link i's frame relative to
its joint, ``inertias[i]`` the central inertia tensor in link i's frame, ``masses[i]`` the mass.
``gravity`` is the gravity acceleration vector in Oxyz (0, 0, -g).

The hot kernels write into a :func:`workspace` allocated once per integration call, so the RK4
loop allocates nothing; the allocating wrappers used by ``model.py`` call the same kernels.

Speed notes (the plant's RK4 step calls :func:`forward_dynamics_into` 40 times per control
period). The workspace is a single array: a numba call receives every array argument as its
fields, and a tuple built for a ``*args`` call is reference-counted array by array on each call,
so few arrays make the calls cheap. Inside the kernels the link rotation, positions, velocities
and forces are tuples of floats (kept in registers) rather than 3-vectors stored into arrays.
No fast-math (not even fused multiply-add): whichever caller a kernel is compiled into, the
same doubles come out, so the graph and the in-process runner agree bit for bit. The reference path
(:func:`metric_terms`, :func:`christoffel_bias`: eq (5) through the Christoffel symbols) keeps
its plain loops and is the independent check of the fast one.

One module of ~500 lines on purpose: the fast path and its reference check are read side by side
(each equation in both), and the kernels share the workspace's layout.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)

Vec = tuple[float, float, float]
Rot = tuple[float, float, float, float, float, float, float, float, float]
"""A rotation matrix as 9 scalars, row-major."""
Sym = tuple[float, float, float, float, float, float]
"""A symmetric 3x3 matrix as (xx, xy, xz, yy, yz, zz)."""

_IDENTITY: Rot = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
_ZERO: Vec = (0.0, 0.0, 0.0)

# Slots of the workspace array ws[0], of shape (_SLOTS, n, max(n, 3)):
_E = 0  # joint axes e_i in Oxyz: [_E, i, :3]
_P = 1  # joint origins p_i: [_P, i, :3]
_T = 2  # quasi-base vectors T_a(i) of the current link (dynamics) or centres r_Ci (frames)
_J = 3  # inertia tensors in Oxyz (frames only): J_i[r, c] = [_J + r, i, c]
_A = 6  # a(q): [_A, :n, :n]
_L = 7  # Cholesky factor (general solve): [_L, :n, :n]
_C = 8  # c(q, qdot), then Q - c: [_C, 0, :n]
_Y = 9  # forward substitution (general solve): [_Y, 0, :n]
_SLOTS = 10


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
def _row(a: np.ndarray, i: int) -> Vec:
    return (a[i, 0], a[i, 1], a[i, 2])


@njit(cache=True, error_model="numpy")
def _slot(ws: np.ndarray, k: int, i: int) -> Vec:
    return (ws[k, i, 0], ws[k, i, 1], ws[k, i, 2])


@njit(cache=True, error_model="numpy")
def _put(ws: np.ndarray, k: int, i: int, v: Vec) -> None:
    ws[k, i, 0] = v[0]
    ws[k, i, 1] = v[1]
    ws[k, i, 2] = v[2]


@njit(cache=True, error_model="numpy")
def _tadd(a: Vec, b: Vec) -> Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, error_model="numpy")
def _tsub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, error_model="numpy")
def _tcross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, error_model="numpy")
def _tdot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, error_model="numpy")
def _rvec(r: Rot, v: Vec) -> Vec:
    """R v."""
    return (r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
            r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
            r[6] * v[0] + r[7] * v[1] + r[8] * v[2])


@njit(cache=True, error_model="numpy")
def _symvec(j: Sym, v: Vec) -> Vec:
    """J v for a symmetric J."""
    return (j[0] * v[0] + j[1] * v[1] + j[2] * v[2],
            j[1] * v[0] + j[3] * v[1] + j[4] * v[2],
            j[2] * v[0] + j[4] * v[1] + j[5] * v[2])


@njit(cache=True, error_model="numpy")
def _rotation(axis: Vec, c: float, s: float) -> Rot:
    """Rotation by the angle of cosine ``c`` and sine ``s`` about the unit vector ``axis``
    (Rodrigues' formula)."""
    v = 1.0 - c
    x, y, z = axis
    return (c + x * x * v, x * y * v - z * s, x * z * v + y * s,
            y * x * v + z * s, c + y * y * v, y * z * v - x * s,
            z * x * v - y * s, z * y * v + x * s, c + z * z * v)


@njit(cache=True, error_model="numpy")
def _compose(r: Rot, s: Rot) -> Rot:
    """R S."""
    return (r[0] * s[0] + r[1] * s[3] + r[2] * s[6], r[0] * s[1] + r[1] * s[4] + r[2] * s[7],
            r[0] * s[2] + r[1] * s[5] + r[2] * s[8],
            r[3] * s[0] + r[4] * s[3] + r[5] * s[6], r[3] * s[1] + r[4] * s[4] + r[5] * s[7],
            r[3] * s[2] + r[4] * s[5] + r[5] * s[8],
            r[6] * s[0] + r[7] * s[3] + r[8] * s[6], r[6] * s[1] + r[7] * s[4] + r[8] * s[7],
            r[6] * s[2] + r[7] * s[5] + r[8] * s[8])


@njit(cache=True, error_model="numpy")
def _world_inertia(r: Rot, inertias: np.ndarray, i: int) -> Sym:
    """R J R^T for link i's central inertia tensor J (symmetric), as 6 scalars."""
    j = inertias[i]
    m0 = (r[0] * j[0, 0] + r[1] * j[1, 0] + r[2] * j[2, 0],
          r[0] * j[0, 1] + r[1] * j[1, 1] + r[2] * j[2, 1],
          r[0] * j[0, 2] + r[1] * j[1, 2] + r[2] * j[2, 2])
    m1 = (r[3] * j[0, 0] + r[4] * j[1, 0] + r[5] * j[2, 0],
          r[3] * j[0, 1] + r[4] * j[1, 1] + r[5] * j[2, 1],
          r[3] * j[0, 2] + r[4] * j[1, 2] + r[5] * j[2, 2])
    m2 = (r[6] * j[0, 0] + r[7] * j[1, 0] + r[8] * j[2, 0],
          r[6] * j[0, 1] + r[7] * j[1, 1] + r[8] * j[2, 1],
          r[6] * j[0, 2] + r[7] * j[1, 2] + r[8] * j[2, 2])
    r0, r1, r2 = (r[0], r[1], r[2]), (r[3], r[4], r[5]), (r[6], r[7], r[8])
    return (_tdot(m0, r0), _tdot(m0, r1), _tdot(m0, r2), _tdot(m1, r1), _tdot(m1, r2),
            _tdot(m2, r2))


@njit(cache=True, error_model="numpy")
def workspace(n: int) -> tuple:
    """Scratch space for the kernels of an ``n``-joint chain (allocated once, reused).

    A 1-tuple holding one array of shape (_SLOTS, n, max(n, 3)), see the ``_E`` .. ``_Y`` slot
    constants: one array, so that passing the workspace to a kernel costs little.
    """
    return (np.empty((_SLOTS, n, max(n, 3))),)


@njit(cache=True, error_model="numpy")
def _frames_kernel(q: np.ndarray, axes: np.ndarray, offsets: np.ndarray, coms: np.ndarray,
                   inertias: np.ndarray, ws: np.ndarray) -> None:
    """Fill ws's e_i, p_i, r_Ci (slot _T) and R_i J_i R_i^T in Oxyz, R_i: link i's rotation."""
    rot = _IDENTITY
    pos = _ZERO
    for i in range(q.shape[0]):
        pos = _tadd(pos, _rvec(rot, _row(offsets, i)))
        axis = _row(axes, i)
        _put(ws, _E, i, _rvec(rot, axis))
        _put(ws, _P, i, pos)
        rot = _compose(rot, _rotation(axis, np.cos(q[i]), np.sin(q[i])))
        _put(ws, _T, i, _tadd(pos, _rvec(rot, _row(coms, i))))
        j = _world_inertia(rot, inertias, i)
        _put(ws, _J, i, (j[0], j[1], j[2]))
        _put(ws, _J + 1, i, (j[1], j[3], j[4]))
        _put(ws, _J + 2, i, (j[2], j[4], j[5]))


@njit(cache=True, error_model="numpy")
def _frames_into(q: np.ndarray, axes: np.ndarray, offsets: np.ndarray, coms: np.ndarray,
                 inertias: np.ndarray, ws: tuple) -> None:
    """Fill a :func:`workspace` with e_i, p_i, r_Ci and the inertia tensors in Oxyz."""
    _frames_kernel(q, axes, offsets, coms, inertias, ws[0])


@njit(cache=True, error_model="numpy")
def _reference_workspace(n: int) -> tuple:
    """Scratch arrays of the reference path :func:`_metric_into` (frames first)."""
    return (workspace(n)[0], np.empty(3), np.empty(3), np.empty(3), np.empty(3),  # vectors
            np.empty((n, 3)), np.empty((n, n, 3)), np.empty((n, n, 3)), np.empty((n, 3)),  # T, dT
            np.empty((n, n)), np.empty((n, n, n)), np.empty(n))  # a, da, qg


@njit(cache=True, error_model="numpy")
def _metric_into(q: np.ndarray, masses: np.ndarray, axes: np.ndarray, offsets: np.ndarray,
                 coms: np.ndarray, inertias: np.ndarray, gravity: np.ndarray,
                 with_derivative: bool, ws: tuple) -> None:
    """Fill ws's a(q), da/dq and Q^g: see :func:`metric_terms`."""
    frames = ws[0]
    _frames_kernel(q, axes, offsets, coms, inertias, frames)
    e, p, rc = frames[_E], frames[_P], frames[_T]
    lever, dlever, tmp, tmp2 = ws[1], ws[2], ws[3], ws[4]
    t, dt, de, je = ws[5], ws[6], ws[7], ws[8]
    a, da, qg = ws[9], ws[10], ws[11]
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
        jw = frames[_J:_J + 3, i]  # J_i in Oxyz (its first 3 columns)
        for al in range(i + 1):
            for c in range(3):
                lever[c] = rc[i, c] - p[al, c]
            _cross(e[al], lever, t[al])
            _matvec(jw, e[al], je[al])
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
    ws = _reference_workspace(q.shape[0])
    ws[10][:, :, :] = 0.0
    _metric_into(q, masses, axes, offsets, coms, inertias, gravity, with_derivative, ws)
    return ws[9].copy(), ws[10].copy(), ws[11].copy()


@njit(cache=True, error_model="numpy")
def chain_frames(q: np.ndarray, axes: np.ndarray, offsets: np.ndarray, coms: np.ndarray,
                 inertias: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Joint axes e_i, joint origins p_i, centres of mass r_Ci and inertia tensors in Oxyz."""
    n = q.shape[0]
    ws = workspace(n)
    _frames_into(q, axes, offsets, coms, inertias, ws)
    frames = ws[0]
    jw = np.empty((n, 3, 3))
    for i in range(n):
        for r in range(3):
            for c in range(3):
                jw[i, r, c] = frames[_J + r, i, c]
    return (frames[_E, :, :3].copy(), frames[_P, :, :3].copy(), frames[_T, :, :3].copy(), jw)


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
def cholesky_into(a: np.ndarray, low: np.ndarray) -> bool:
    """The Cholesky factor L of a symmetric positive definite ``a`` (a = L L^T, from a's lower
    triangle) into the lower triangle of ``low``; False (``low`` partly written) when a pivot
    is <= 0, i.e. ``a`` is not positive definite. The package's one Cholesky factorisation."""
    n = a.shape[0]
    for i in range(n):
        for j in range(i + 1):
            s = a[i, j]
            for k in range(j):
                s -= low[i, k] * low[j, k]
            if i == j:
                if s <= 0.0:
                    return False
                low[i, i] = np.sqrt(s)
            else:
                low[i, j] = s / low[j, j]
    return True


@njit(cache=True, error_model="numpy")
def _solve_spd_into(a: np.ndarray, b: np.ndarray, low: np.ndarray, y: np.ndarray,
                    x: np.ndarray) -> None:
    n = b.shape[0]
    if not cholesky_into(a, low):
        raise ValueError("metric tensor is not positive definite")
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
def _solve_spd3(a00: float, a10: float, a11: float, a20: float, a21: float, a22: float,
                b0: float, b1: float, b2: float) -> Vec:
    """:func:`_solve_spd_into` for 3x3 on scalars (lower triangle): a = L D L^T, no square roots.

    The pivots d_k are the squares of the Cholesky diagonal, so a pivot <= 0 is the same "not
    positive definite" failure.
    """
    if a00 <= 0.0:
        raise ValueError("metric tensor is not positive definite")
    r0 = 1.0 / a00
    l10 = a10 * r0
    l20 = a20 * r0
    d1 = a11 - l10 * a10
    if d1 <= 0.0:
        raise ValueError("metric tensor is not positive definite")
    r1 = 1.0 / d1
    s21 = a21 - l20 * a10
    l21 = s21 * r1
    d2 = a22 - l20 * a20 - l21 * s21
    if d2 <= 0.0:
        raise ValueError("metric tensor is not positive definite")
    y1 = b1 - l10 * b0
    x2 = (b2 - l20 * b0 - l21 * y1) / d2
    x1 = y1 * r1 - l21 * x2
    return (b0 * r0 - l10 * x1 - l20 * x2, x1, x2)


@njit(cache=True, error_model="numpy")
def solve_spd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve a x = b for a symmetric positive definite ``a`` (Cholesky; unrolled for 3x3)."""
    n = b.shape[0]
    x = np.empty(n)
    if n == 3:
        x[0], x[1], x[2] = _solve_spd3(a[0, 0], a[1, 0], a[1, 1], a[2, 0], a[2, 1], a[2, 2],
                                       b[0], b[1], b[2])
    else:
        _solve_spd_into(a, b, np.empty((n, n)), np.empty(n), x)
    return x


@njit(cache=True, error_model="numpy", inline="always")
def _inertia_bias_kernel(q: np.ndarray, qd: np.ndarray, masses: np.ndarray, axes: np.ndarray,
                         offsets: np.ndarray, coms: np.ndarray, inertias: np.ndarray,
                         gravity: np.ndarray, ws: np.ndarray, bias: np.ndarray) -> None:
    """The outward pass of :func:`inertia_and_bias_into`, eqs (2)-(4), (6), (7): a(q) into
    slot _A of ``ws``, c(q, qdot) into ``bias``.

    The link rotation R_i, r_Ci, the inertia tensor R_i J_i R_i^T in Oxyz and the velocities
    are tuples of floats; only e_a and p_a (read again by the later links) and the T_a(i) of
    the current link are stored, in ``ws``. Link i reads q_i and qdot_i before it writes c_a,
    a <= i, so ``bias`` may be ``q`` or ``qd``.
    """
    n = q.shape[0]
    rot = _IDENTITY  # rotation of link i-1, then i
    pi = _ZERO  # joint origin p_i
    w = _ZERO  # angular velocity of link i-1, then i
    wb = _ZERO  # its angular acceleration at qdd = 0
    pb = (-gravity[0], -gravity[1], -gravity[2])  # acceleration of p_i at qdd = 0, minus g
    for i in range(n):
        axis = _row(axes, i)
        if i == 0:  # the base frame is Oxyz
            d = _row(offsets, 0)
            ei = axis
            rot = _rotation(axis, np.cos(q[0]), np.sin(q[0]))
        else:
            d = _rvec(rot, _row(offsets, i))  # p_i - p_{i-1}
            pb = _tadd(pb, _tadd(_tcross(wb, d), _tcross(w, _tcross(w, d))))
            ei = _rvec(rot, axis)
            rot = _compose(rot, _rotation(axis, np.cos(q[i]), np.sin(q[i])))
        pi = _tadd(pi, d)
        _put(ws, _E, i, ei)
        _put(ws, _P, i, pi)
        de = _tcross(w, ei)  # d e_i / dt = w_{i-1} x e_i
        s = qd[i]
        wb = (wb[0] + de[0] * s, wb[1] + de[1] * s, wb[2] + de[2] * s)
        w = (w[0] + ei[0] * s, w[1] + ei[1] * s, w[2] + ei[2] * s)
        d = _rvec(rot, _row(coms, i))  # r_Ci - p_i
        ci = _tadd(pi, d)
        x1 = _tcross(wb, d)
        x2 = _tcross(w, _tcross(w, d))
        mi = masses[i]
        f = (mi * (pb[0] + x1[0] + x2[0]), mi * (pb[1] + x1[1] + x2[1]),
             mi * (pb[2] + x1[2] + x2[2]))
        jw = _world_inertia(rot, inertias, i)
        tau = _tadd(_tcross(w, _symvec(jw, w)), _symvec(jw, wb))
        for al in range(i + 1):
            ea = _slot(ws, _E, al)
            ta = _tcross(ea, _tsub(ci, _slot(ws, _P, al)))
            _put(ws, _T, al, ta)
            jea = _symvec(jw, ea)
            x = _tdot(ta, f) + _tdot(ea, tau)
            # link al is the first to contribute to c_al and to a_ab, b <= al
            bias[al] = x if al == i else bias[al] + x
            for be in range(al + 1):
                x = mi * _tdot(ta, _slot(ws, _T, be)) + _tdot(jea, _slot(ws, _E, be))
                ws[_A, al, be] = x if al == i else ws[_A, al, be] + x
    for al in range(n):
        for be in range(al + 1, n):
            ws[_A, al, be] = ws[_A, be, al]


@njit(cache=True, error_model="numpy")
def inertia_and_bias_into(q: np.ndarray, qd: np.ndarray, masses: np.ndarray, axes: np.ndarray,
                          offsets: np.ndarray, coms: np.ndarray, inertias: np.ndarray,
                          gravity: np.ndarray, ws: tuple, bias: np.ndarray) -> np.ndarray:
    """Fill ``bias`` with c(q, qdot) of eq (7); return a(q) (a view of ``ws``).

    a(q) by eq (2) from the quasi-base vectors T_a(i) = e_a x (r_Ci - p_a), Omega_a(i) = e_a,
    eqs (3)-(4). c is evaluated without forming Gamma: sum_ab Gamma_{ab,c} qdot_a qdot_b equals
    the projection onto the quasi-base vectors of the velocity-product accelerations,
    sum_i T_c(i) . m_i b_i + Omega_c(i) . (J_i dw_i + w_i x J_i w_i), with b_i the centre of
    mass acceleration and dw_i the angular acceleration at qdd = 0, computed outward along the
    chain in O(n) (tested equal to the eq (5) contraction). Gravity enters as -Q^g, eq (6), as
    the base acceleration -g of the outward pass. Kernel: :func:`_inertia_bias_kernel`.
    """
    buf = ws[0]
    _inertia_bias_kernel(q, qd, masses, axes, offsets, coms, inertias, gravity, buf, bias)
    return buf[_A, :q.shape[0], :q.shape[0]]


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
def forward_dynamics_into(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, arm: tuple,
                          ws: tuple, out: np.ndarray) -> None:
    """qdd of eq (8), a(q) qdd = Q - c(q, qdot), written into ``out``; ``arm`` is a model's
    ``kernel_args`` (masses, axes, offsets, coms, inertias, gravity).

    a and c by :func:`_inertia_bias_kernel` (see :func:`inertia_and_bias_into`); the solve is
    the unrolled 3x3 :func:`_solve_spd3` for the arm, the general Cholesky otherwise.
    """
    buf = ws[0]
    masses, axes, offsets, coms, inertias, gravity = arm
    _inertia_bias_kernel(q, qd, masses, axes, offsets, coms, inertias, gravity, buf, buf[_C, 0])
    n = q.shape[0]
    if n == 3:
        out[0], out[1], out[2] = _solve_spd3(
            buf[_A, 0, 0], buf[_A, 1, 0], buf[_A, 1, 1], buf[_A, 2, 0], buf[_A, 2, 1],
            buf[_A, 2, 2], effort[0] - buf[_C, 0, 0], effort[1] - buf[_C, 0, 1],
            effort[2] - buf[_C, 0, 2])
    else:
        for j in range(n):
            buf[_C, 0, j] = effort[j] - buf[_C, 0, j]
        _solve_spd_into(buf[_A, :n, :n], buf[_C, 0, :n], buf[_L, :n, :n], buf[_Y, 0, :n], out)
