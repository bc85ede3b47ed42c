"""One trial's filtered regression for the identification of the patient's joint forces
(:mod:`.identification`, whose docstring gives the model): the arm's momentum and Lagrange
terms, the state-variable filter, the columns, the reflex grid's columns."""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.dynamics import metric_terms
from ..arm.model import ArmModel
from .identification_settings import IdentificationSettings


def scipy_signal() -> ModuleType:
    """``scipy.signal``, imported where a filter is first made or run: importing it takes
    0.3-1 s (scipy.stats with it), which a run without a Q-filter or identification, and every
    command's start-up, would pay for nothing."""
    return importlib.import_module("scipy.signal")


@njit(cache=True, error_model="numpy")
def lagrangian_terms(q: np.ndarray, qd: np.ndarray, masses: np.ndarray, axes: np.ndarray,
                     offsets: np.ndarray, coms: np.ndarray, inertias: np.ndarray,
                     gravity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At every sample of (q, qdot) (rows): the momentum p = a(q) qdot and
    w_c = -1/2 qdot^T (d a / d q_c) qdot - Q^g_c, so that d p / d t + w = a(q) qddot + c(q, qdot)
    of eqs (7)-(8) (Lagrange's equations; a, d a / d q, Q^g by :func:`dynamics.metric_terms`,
    eqs (2)-(6))."""
    n_samples, n = q.shape
    p = np.zeros((n_samples, n))
    w = np.zeros((n_samples, n))
    for i in range(n_samples):
        a, da, qg = metric_terms(q[i], masses, axes, offsets, coms, inertias, gravity, True)
        v = qd[i]
        for r in range(n):
            s = 0.0
            for c in range(n):
                s += a[r, c] * v[c]
            p[i, r] = s
            quad = 0.0
            for al in range(n):
                for be in range(n):
                    quad += da[r, al, be] * v[al] * v[be]
            w[i, r] = -0.5 * quad - qg[r]
    return p, w


class RegressionFilters:
    """H(s) = w_f^2 / (s + w_f)^2 and s H(s) discretised at the control period."""

    def __init__(self, settings: IdentificationSettings) -> None:
        wf = settings.filter_bandwidth
        h = ([wf * wf], [1.0, 2.0 * wf, wf * wf])
        dh = ([wf * wf, 0.0], [1.0, 2.0 * wf, wf * wf])
        self.held = self._discrete(h, settings.period, "zoh")
        self.smooth = self._discrete(h, settings.period, "foh")
        self.derivative = self._discrete(dh, settings.period, "foh")
        self.smoothing = scipy_signal().butter(4, settings.smoothing_cutoff,
                                               fs=1.0 / settings.period, output="sos")

    @staticmethod
    def _discrete(tf: tuple[list[float], list[float]], period: float,
                  method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        num, den, _ = scipy_signal().cont2discrete(tf, period, method=method)
        b = np.asarray(num, dtype=float).ravel()
        a = np.asarray(den, dtype=float).ravel()
        return b, a, scipy_signal().lfilter_zi(b, a)

    def start_transients(self, samples: int) -> np.ndarray:
        """(samples, 2), orthonormal columns spanning 1 - (step response of H) under both
        discretisations: what a filter started at rest at its first value leaves when the arm
        was not at rest at the trial's start (its first acceleration is unknown, so each
        trial's amount of it is projected out, not identified)."""
        ones = np.ones(samples)
        shapes = np.column_stack([ones - scipy_signal().lfilter(*self.held[:2], ones),
                                  ones - scipy_signal().lfilter(*self.smooth[:2], ones)])
        return np.asarray(np.linalg.qr(shapes)[0])

    @staticmethod
    def apply(filt: tuple[np.ndarray, np.ndarray, np.ndarray], x: np.ndarray) -> np.ndarray:
        """Filter along axis 0, starting at rest at the first sample's value."""
        b, a, zi = filt
        shape = (zi.shape[0],) + (1,) * (x.ndim - 1)
        out, _ = scipy_signal().lfilter(b, a, x, axis=0, zi=zi.reshape(shape) * x[:1])
        return np.asarray(out)


@dataclass(frozen=True, eq=False)
class TrialRegressors:
    """One trial's filtered regression y = Phi theta, per joint, after the burn-in."""

    target: np.ndarray
    """(m, n): H[u] - H[a_N qddot + c_N], the torque the nominal arm does not explain."""
    base: np.ndarray
    """(m, n, 7): the columns of :data:`.identification_settings.BASE_PARAMETERS`."""
    velocity: np.ndarray
    """(N+1, n): the smoothed velocity the nonlinear columns were built from (whole trial)."""
    skip: int
    """Samples left out at the start (burn-in)."""
    transients: np.ndarray
    """(m, 2) orthonormal: the start transients projected out of every column."""
    unresolved: np.ndarray
    """(n,) rad: RMS of the measured position above the smoothing cutoff (the motion the
    regressors do not resolve: encoder noise, or chatter and stick-slip when large)."""
    hard_coulomb: np.ndarray
    """(m, n): the Coulomb column under a hard law, H[sgn(qdot)] (MuJoCo's ``frictionloss``,
    a dry contact's), where the model's is H[tanh(qdot / v_s)]: the other law the friction
    law's model error is measured against (:mod:`.identification`)."""


def trial_regressors(nominal: ArmModel, settings: IdentificationSettings,
                     position: np.ndarray, effort: np.ndarray,
                     filters: RegressionFilters | None = None,
                     reference: tuple[np.ndarray, np.ndarray] | None = None) -> TrialRegressors:
    """The filtered regression of one trial (module docstring) from its measured position and
    commanded effort, both (N+1, n), and the reference (q_d, qdot_d) it tracked (None: no
    voluntary columns)."""
    filters = filters or RegressionFilters(settings)
    q = np.ascontiguousarray(position, dtype=float)
    u = np.asarray(effort, dtype=float)
    period = settings.period
    smoothed = scipy_signal().sosfiltfilt(filters.smoothing, q, axis=0)
    velocity = np.gradient(smoothed, period, axis=0)
    p, w = lagrangian_terms(np.ascontiguousarray(smoothed), np.ascontiguousarray(velocity),
                            *nominal.kernel_args)
    d = settings.effort_delay
    applied = u if d == 0 else np.concatenate([np.repeat(u[:1], d, axis=0), u[:-d]])
    nominal_torque = filters.apply(filters.derivative, p) + filters.apply(filters.smooth, w)
    target = filters.apply(filters.held, applied) - nominal_torque
    columns = np.stack([
        filters.apply(filters.derivative, q),
        filters.apply(filters.smooth, np.tanh(velocity / settings.stribeck_velocity)),
        filters.apply(filters.smooth, q),
        np.ones_like(q),
        nominal_torque if settings.model_scale else np.zeros_like(q),
        *_voluntary_columns(settings, filters, q, velocity, reference),
    ], axis=2)
    skip = min(int(round(settings.burn_in / period)), q.shape[0] - 1)
    basis = filters.start_transients(q.shape[0])[skip:]
    unresolved = np.sqrt(np.mean((q - smoothed)[skip:] ** 2, axis=0))
    hard = filters.apply(filters.smooth, np.sign(velocity))
    return TrialRegressors(project_out(target[skip:], basis), project_out(columns[skip:], basis),
                           velocity, skip, basis, unresolved, project_out(hard[skip:], basis))


def _voluntary_columns(settings: IdentificationSettings, filters: RegressionFilters, q: np.ndarray,
                       velocity: np.ndarray,
                       reference: tuple[np.ndarray, np.ndarray] | None) -> list[np.ndarray]:
    """-H[L[q_d - q]] and -H[L[qdot_d - qdot]]: the patient's lagged effort toward the
    reference (it adds to the command, so it enters the resisting torque with a minus), held
    over each period; zero without a reference."""
    if reference is None:
        return [np.zeros_like(q), np.zeros_like(q)]
    q_ref = np.asarray(reference[0], dtype=float)
    qd_ref = np.asarray(reference[1], dtype=float)
    if q_ref.shape != q.shape or qd_ref.shape != q.shape:
        raise ValueError(f"the reference must be {q.shape}, got {q_ref.shape}, {qd_ref.shape}")
    a = settings.period / (settings.voluntary_lag + settings.period)
    lagged = [scipy_signal().lfilter([a], [1.0, a - 1.0], x, axis=0)
              for x in (q_ref - q, qd_ref - velocity)]
    return [-filters.apply(filters.held, np.asarray(x)) for x in lagged]


def project_out(x: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """``x`` (along axis 0) minus its least-squares projection on the columns of ``basis``
    (orthonormal)."""
    flat = np.ascontiguousarray(x).reshape(x.shape[0], -1)
    return np.asarray((flat - basis @ (basis.T @ flat)).reshape(x.shape))


def reflex_columns(velocity: np.ndarray, thresholds: np.ndarray, delays: tuple[int, ...],
                   filters: RegressionFilters, skip: int) -> np.ndarray:
    """(m, delays x thresholds): H[sgn(v) max(0, abs(v) - v_th)] with v = qdot(t - tau_r), held
    over each period (the first value before the trial's start), for one joint's velocity.

    Filtered once undelayed: a filter started at rest at its first value answers the delayed
    column with that rest value for ``delay`` samples, then with the undelayed answer shifted."""
    n_samples = velocity.shape[0]
    excess = np.maximum(np.abs(velocity)[:, None] - thresholds[None, :], 0.0)
    filtered = filters.apply(filters.held, np.sign(velocity)[:, None] * excess)
    width = thresholds.shape[0]
    out = np.empty((n_samples, len(delays) * width))
    for k, delay in enumerate(delays):
        block = out[:, k * width:(k + 1) * width]
        block[:delay] = filtered[0]
        block[delay:] = filtered[:n_samples - delay]
    return out[skip:]
