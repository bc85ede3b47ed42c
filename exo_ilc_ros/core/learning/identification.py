"""Between-trial identification of the patient's joint forces: eq (6)'s Q^v, Q^c, Q^f (viscous
friction, joint stiffness, Coulomb friction), which the paper sets to zero, and the stretch reflex,
per joint, from one trial's commanded effort and measured position, recursive over trials.

The model, per joint j (the virtual patient's, :mod:`exo_ilc_ros.core.patient`), with the arm's
own dynamics of eq (8) written in Lagrange's form so that no acceleration is needed::

    u_j(t - d T) = p_j' + w_j + tau_p,j,   p = a_N(q) qdot,
    w_j = -1/2 qdot^T (d a_N / d q_j) qdot - Q^g_j,
    tau_p,j = B qdot_j + F_c tanh(qdot_j / v_s) + K q_j + c + delta (p_j' + w_j)
              + G sgn(v) max(0, abs(v) - v_th),   v = qdot_j(t - tau_r),
              [- K_v L[q_d,j - q_j] - D_v L[qdot_d,j - qdot_j]]

(a_N, Q^g the nominal model's eqs (2) and (6); p_j' + w_j equals a_N qddot + c_N of eq (7),
tested) with K (q_j - q_0) = K q_j + c, so q_0 = -c / K; delta: the plant's mass error along
the nominal torque (a uniform mass error, eq (15), is exactly this term); d: the actuator's
delay in control periods, known. The reflex (G, v_th, tau_r) is held over each period, as the
virtual patient holds it. The bracket, the patient's own effort toward the reference (L a
first-order lag), is fitted only with ``voluntary=True``; otherwise it tests the estimate.

**Filtered regressors** (state-variable filter): every signal passes through the same
H(s) = w_f^2 / (s + w_f)^2, so the derivative p' enters as (s H)[p], a proper filter of p, and
qdot_j's column as (s H)[q_j]: no acceleration, and no velocity where a position does. The
nonlinear columns (tanh, reflex) and p, w are built from a zero-phase low-passed position (the
whole trial is at hand between trials) and its central difference, then filtered by H; the
measured velocity is not used (its filter may lag). The held effort and the held reflex are
filtered by H's zero-order-hold discretisation, the smooth signals by its first-order-hold one;
every filter starts at rest at its signal's first value.

**Recursive least squares over trials** in information form (per joint; forgetting once per
trial, lambda in (0, 1]): R_k = lambda R_{k-1} + Phi_k^T Phi_k, b_k = lambda b_{k-1} +
Phi_k^T y_k, theta_k = R_k^-1 b_k. A trial whose own regressor is ill-conditioned is added
without forgetting (no wind-up of the directions it does not excite). The reflex's threshold and
delay enter nonlinearly: the information of every (v_th, tau_r) on a grid is kept, and the one of
least residual wins (separable least squares); G is linear.

**Confidence**: Cov(theta) = s^2 R^-1 (sum lambda^2m / sum lambda^m), s^2 = RSS / (n - p),
each variance inflated by the last trials' ratio of the autocorrelation-robust (Newey-West,
Bartlett kernel) to the naive variance (filtered residuals are strongly autocorrelated);
95 % intervals +-1.96 SE; q_0's by the delta method; v_th's and tau_r's from the residual's
profile over the grid. **Trust**: the condition number of the column-scaled information matrix,
each parameter's variance inflation (collinearity), excitation, precision and physical bounds,
and no sign of the patient's own effort in the residual (:class:`IdentificationSettings`); an
estimate that fails any of them says why and is not usable (:attr:`JointEstimate.trustworthy`).
A trial with non-finite samples, or where any joint moved faster than the regression resolves
(chatter, which biases every coupled joint), is refused and changes nothing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from scipy import signal

from exo_ilc_ros.core.config import Config
from exo_ilc_ros.core.dynamics import metric_terms
from exo_ilc_ros.core.laws import TrialRecord
from exo_ilc_ros.core.model import ArmModel

PASSIVE_PARAMETERS = ("viscous", "coulomb", "stiffness", "offset", "model_scale")
"""The linear parameters a usable estimate needs, in column order."""
BASE_PARAMETERS = (*PASSIVE_PARAMETERS, "voluntary_stiffness", "voluntary_damping")
"""Every joint's linear columns: the passive ones, then the patient's own effort (nuisance
parameters, zero columns when no reference is given)."""
PARAMETERS = ("viscous", "coulomb", "stiffness", "rest_position", "offset", "model_scale",
              "voluntary_stiffness", "voluntary_damping", "reflex_gain", "reflex_threshold",
              "reflex_delay")
"""Every parameter a :class:`JointEstimate` reports."""
UNITS = {"viscous": "N m s/rad", "coulomb": "N m", "stiffness": "N m/rad",
         "rest_position": "rad", "offset": "N m", "model_scale": "1",
         "voluntary_stiffness": "N m/rad", "voluntary_damping": "N m s/rad",
         "reflex_gain": "N m s/rad", "reflex_threshold": "rad/s", "reflex_delay": "s"}
_PHYSICAL = ("viscous", "coulomb", "stiffness", "reflex_gain")
"""Parameters that cannot be negative."""
_Z95 = 1.959963984540054


def _default_thresholds() -> tuple[float, ...]:
    return tuple(float(x) for x in np.round(np.arange(0.05, 1.0 + 1e-9, 0.025), 6))


def _default_precision() -> dict[str, float]:
    return {"viscous": 0.02, "coulomb": 0.02, "stiffness": 0.1, "rest_position": 0.05,
            "offset": 0.02, "model_scale": 0.01, "reflex_gain": 0.05}


def _default_bounds() -> dict[str, tuple[float, float]]:
    return {"viscous": (0.0, 20.0), "coulomb": (0.0, 10.0), "stiffness": (0.0, 100.0),
            "rest_position": (-math.pi, math.pi), "model_scale": (-0.5, 0.5),
            "reflex_gain": (0.0, 20.0)}


@dataclass(frozen=True)
class IdentificationSettings:
    """How the identification filters, forgets and judges (module docstring)."""

    period: float = 0.01
    """T (s): the control period of the samples."""
    stribeck_velocity: float = 0.1
    """v_s (rad/s) of the Coulomb column tanh(qdot / v_s) (MAHI Open Exo's tanh(10 qdot))."""
    filter_bandwidth: float = 2.0 * math.pi * 4.0
    """w_f (rad/s) of H(s) = w_f^2 / (s + w_f)^2: above the movement's band (a 5 s quintic's
    energy is below ~1 Hz), below the loop's noise (4 Hz: the least error on the virtual
    patient over 1-6 Hz, docs/patient-identification.md)."""
    smoothing_cutoff: float = 10.0
    """Hz: the zero-phase low-pass (4th-order Butterworth, forward and backward) of the
    position the nonlinear columns and the arm's momentum are built from."""
    forgetting: float = 0.9
    """lambda per trial: memory ~1 / (1 - lambda) trials (0.9: ~10)."""
    effort_delay: int = 0
    """Control periods between a command and its torque at the joint (known, not identified)."""
    burn_in: float = 0.3
    """s at each trial's start left out (the filters' start, and a learned feed-forward's
    first samples, which shake the arm faster than the first-order hold follows)."""
    model_scale: bool = True
    """Identify delta (the plant's mass error along the nominal torque); False: trust a_N."""
    reflex: bool = True
    """Identify the stretch reflex (G, v_th, tau_r)."""
    voluntary: bool = False
    """With the trial's reference: columns for the patient's own effort toward it,
    -L[q_d - q] and -L[qdot_d - qdot] (L: a first-order lag), so that it is not taken for
    stiffness and damping. Off by default: for a passive patient these columns are nearly
    collinear with the passive ones while the learning converges (the damping then misses
    10 %); on for a patient known to push (docs/patient-identification.md)."""
    voluntary_minimum_torque: float = 1e-3
    """N m RMS: the least torque the voluntary columns must explain (when not fitted) for the
    estimate to be suspected of holding the patient's own effort (the shipped scenarios:
    noise-free friction 2e-5, voluntary and realistic 3e-3 to 3e-2)."""
    voluntary_lag: float = 0.15
    """s: the time constant of L (the virtual patient's voluntary.time_constant of
    ``voluntary.yaml``)."""
    reflex_thresholds: tuple[float, ...] = field(default_factory=_default_thresholds)
    """v_th grid (rad/s)."""
    reflex_delays: tuple[float, ...] = (0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.11, 0.12, 0.13,
                                        0.14, 0.15)
    """tau_r grid (s), rounded to control periods (the virtual patient's 0.1 s in the middle)."""
    max_condition: float = 1000.0
    """Largest condition number of the column-scaled information matrix (sqrt of the
    eigenvalue ratio: the regressor's own condition number) of a usable estimate."""
    max_variance_inflation: float = 1000.0
    """Largest variance inflation factor of a parameter (its variance over the variance it
    would have with a column orthogonal to the others): above it the parameter is not
    identifiable from this excitation (collinear with another)."""
    relative_precision: float = 0.1
    """Largest 95 % half-width over abs(value) of a usable parameter (the accuracy issue 28
    asks for) ..."""
    absolute_precision: Mapping[str, float] = field(default_factory=_default_precision)
    """... unless the half-width is below this (a parameter near zero)."""
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=_default_bounds)
    """Plausible range of each parameter; an estimate beyond it by more than three standard
    errors (and more than its absolute precision) is absurd and never usable."""
    max_unresolved_motion: float = 5e-4
    """rad: the largest RMS of the measured position above the smoothing cutoff, on any joint,
    of a trial that is used (a 14-bit encoder's quantisation is 1.1e-4; a chattering spastic
    elbow 2e-3 to 7e-3, where the filtered regression is biased on every coupled joint)."""
    reflex_minimum_torque: float = 0.02
    """N m: a reflex is reported only if its fitted torque at the fastest stretch seen
    exceeds this (and G's interval excludes 0)."""

    def __post_init__(self) -> None:
        if not self.period > 0.0:
            raise ValueError("identification: period must be > 0")
        if not 0.0 < self.forgetting <= 1.0:
            raise ValueError("identification: forgetting must be in (0, 1]")
        if not (self.filter_bandwidth > 0.0 and self.stribeck_velocity > 0.0):
            raise ValueError("identification: filter bandwidth and Stribeck velocity must be > 0")
        if not 0.0 < self.smoothing_cutoff < 0.5 / self.period:
            raise ValueError("identification: the smoothing cutoff must be below Nyquist")
        if self.effort_delay < 0:
            raise ValueError("identification: effort_delay must be >= 0")

    @classmethod
    def from_config(cls, config: Config, **changes: Any) -> IdentificationSettings:
        """The defaults at the config's control period and actuator delay (the plant's
        ``patient.effort_delay``: known on an arm from its drive, not identified), with
        ``changes``."""
        values: dict[str, Any] = {"period": float(config["control.period"]),
                                  "effort_delay": int(config["patient.effort_delay"])}
        values.update(changes)
        return cls(**values)

    @property
    def delay_samples(self) -> tuple[int, ...]:
        """The reflex delay grid in control periods (distinct, sorted)."""
        return tuple(sorted({int(round(d / self.period)) for d in self.reflex_delays}))


@dataclass(frozen=True)
class ParameterEstimate:
    """One identified parameter with its 95 % interval and whether it may be used."""

    name: str
    value: float
    standard_error: float
    low: float
    high: float
    identifiable: bool
    """The excitation determines it (excited, not collinear with another parameter)."""
    trustworthy: bool
    """Identifiable, finite, precise and physically plausible: usable."""
    reason: str = ""
    """Why not trustworthy ("" when it is)."""

    @property
    def unit(self) -> str:
        """The parameter's unit."""
        return UNITS[self.name]


@dataclass(frozen=True)
class JointEstimate:
    """Everything identified for one joint after the trials so far."""

    joint: int
    parameters: Mapping[str, ParameterEstimate]
    """By name, every entry of :data:`PARAMETERS`."""
    reflex_detected: bool
    condition_number: float
    """Of the column-scaled information matrix of the model reported."""
    residual_rms: float
    """N m: RMS of the filtered torque the model leaves unexplained."""
    peak_stretch_velocity: float
    """rad/s: the fastest abs(qdot) of every trial so far (what excited the reflex)."""
    trials: int
    trustworthy: bool
    """Every parameter the joint-force term needs (viscous, Coulomb, stiffness, rest position,
    offset and the reflex when detected) is trustworthy."""
    reasons: tuple[str, ...]
    """Why not trustworthy (empty when it is)."""

    def __getitem__(self, name: str) -> ParameterEstimate:
        return self.parameters[name]

    def value(self, name: str) -> float:
        """The estimate of ``name``."""
        return self.parameters[name].value


@dataclass(frozen=True)
class PatientEstimate:
    """The identification after a trial: one :class:`JointEstimate` per joint."""

    trial: int
    joints: tuple[JointEstimate, ...]
    rejected: str = ""
    """Why the last trial's data was not used ("": it was)."""

    @property
    def trustworthy(self) -> bool:
        """Every joint's estimate is usable."""
        return all(j.trustworthy for j in self.joints)

    def values(self, name: str) -> np.ndarray:
        """``name``'s estimate on every joint."""
        return np.array([j.value(name) for j in self.joints])

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-able values (non-finite numbers as None), for a summary, a bag or
        ``/diagnostics``: per joint every parameter's value, standard error, interval,
        identifiable, trustworthy and reason, and the joint's condition number, residual,
        peak stretch velocity, trials, trustworthy and reasons."""
        return {"trial": self.trial, "rejected": self.rejected,
                "trustworthy": self.trustworthy,
                "joints": [{"joint": j.joint, "trustworthy": j.trustworthy,
                            "reasons": list(j.reasons), "reflex_detected": j.reflex_detected,
                            "condition_number": _plain(j.condition_number),
                            "residual_rms": _plain(j.residual_rms),
                            "peak_stretch_velocity": _plain(j.peak_stretch_velocity),
                            "trials": j.trials,
                            "parameters": {name: {"value": _plain(p.value),
                                                  "standard_error": _plain(p.standard_error),
                                                  "low": _plain(p.low), "high": _plain(p.high),
                                                  "unit": p.unit,
                                                  "identifiable": bool(p.identifiable),
                                                  "trustworthy": bool(p.trustworthy),
                                                  "reason": p.reason}
                                           for name, p in j.parameters.items()}}
                           for j in self.joints]}


def _plain(x: float) -> float | None:
    """A finite float, or None."""
    x = float(x)
    return x if math.isfinite(x) else None


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


class _Filters:
    """H(s) = w_f^2 / (s + w_f)^2 and s H(s) discretised at the control period."""

    def __init__(self, settings: IdentificationSettings) -> None:
        wf = settings.filter_bandwidth
        h = ([wf * wf], [1.0, 2.0 * wf, wf * wf])
        dh = ([wf * wf, 0.0], [1.0, 2.0 * wf, wf * wf])
        self.held = self._discrete(h, settings.period, "zoh")
        self.smooth = self._discrete(h, settings.period, "foh")
        self.derivative = self._discrete(dh, settings.period, "foh")
        self.smoothing = signal.butter(4, settings.smoothing_cutoff, fs=1.0 / settings.period,
                                       output="sos")

    @staticmethod
    def _discrete(tf: tuple[list[float], list[float]], period: float,
                  method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        num, den, _ = signal.cont2discrete(tf, period, method=method)
        b = np.asarray(num, dtype=float).ravel()
        a = np.asarray(den, dtype=float).ravel()
        return b, a, signal.lfilter_zi(b, a)

    def start_transients(self, samples: int) -> np.ndarray:
        """(samples, 2), orthonormal columns spanning 1 - (step response of H) under both
        discretisations: what a filter started at rest at its first value leaves when the arm
        was not at rest at the trial's start (its first acceleration is unknown, so each
        trial's amount of it is projected out, not identified)."""
        ones = np.ones(samples)
        shapes = np.column_stack([ones - signal.lfilter(*self.held[:2], ones),
                                  ones - signal.lfilter(*self.smooth[:2], ones)])
        return np.asarray(np.linalg.qr(shapes)[0])

    @staticmethod
    def apply(filt: tuple[np.ndarray, np.ndarray, np.ndarray], x: np.ndarray) -> np.ndarray:
        """Filter along axis 0, starting at rest at the first sample's value."""
        b, a, zi = filt
        shape = (zi.shape[0],) + (1,) * (x.ndim - 1)
        out, _ = signal.lfilter(b, a, x, axis=0, zi=zi.reshape(shape) * x[:1])
        return np.asarray(out)


@dataclass(frozen=True, eq=False)
class TrialRegressors:
    """One trial's filtered regression y = Phi theta, per joint, after the burn-in."""

    target: np.ndarray
    """(m, n): H[u] - H[a_N qddot + c_N], the torque the nominal arm does not explain."""
    base: np.ndarray
    """(m, n, 7): the columns of :data:`BASE_PARAMETERS`."""
    velocity: np.ndarray
    """(N+1, n): the smoothed velocity the nonlinear columns were built from (whole trial)."""
    skip: int
    """Samples left out at the start (burn-in)."""
    transients: np.ndarray
    """(m, 2) orthonormal: the start transients projected out of every column."""
    unresolved: np.ndarray
    """(n,) rad: RMS of the measured position above the smoothing cutoff (the motion the
    regressors do not resolve: encoder noise, or chatter and stick-slip when large)."""


def trial_regressors(nominal: ArmModel, settings: IdentificationSettings,
                     position: np.ndarray, effort: np.ndarray,
                     filters: _Filters | None = None,
                     reference: tuple[np.ndarray, np.ndarray] | None = None) -> TrialRegressors:
    """The filtered regression of one trial (module docstring) from its measured position and
    commanded effort, both (N+1, n), and the reference (q_d, qdot_d) it tracked (None: no
    voluntary columns)."""
    filters = filters or _Filters(settings)
    q = np.ascontiguousarray(position, dtype=float)
    u = np.asarray(effort, dtype=float)
    period = settings.period
    smoothed = signal.sosfiltfilt(filters.smoothing, q, axis=0)
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
    return TrialRegressors(_project_out(target[skip:], basis), _project_out(columns[skip:], basis),
                           velocity, skip, basis, unresolved)


def _voluntary_columns(settings: IdentificationSettings, filters: _Filters, q: np.ndarray,
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
    lagged = [signal.lfilter([a], [1.0, a - 1.0], x, axis=0)
              for x in (q_ref - q, qd_ref - velocity)]
    return [-filters.apply(filters.held, np.asarray(x)) for x in lagged]


def _project_out(x: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """``x`` (along axis 0) minus its least-squares projection on the columns of ``basis``
    (orthonormal)."""
    flat = np.ascontiguousarray(x).reshape(x.shape[0], -1)
    return np.asarray((flat - basis @ (basis.T @ flat)).reshape(x.shape))


def reflex_columns(velocity: np.ndarray, thresholds: np.ndarray, delays: tuple[int, ...],
                   filters: _Filters, skip: int) -> np.ndarray:
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


@dataclass
class _Solution:
    theta: np.ndarray
    """Per column (nan where not excited)."""
    covariance_scaled: np.ndarray
    """pinv of the column-scaled information of the excited columns, full size (nan rows)."""
    scale: np.ndarray
    excited: np.ndarray
    condition: float
    rss: float


def _solve(R: np.ndarray, b: np.ndarray, yy: float,
           fitted: np.ndarray | None = None) -> _Solution:
    """theta = R^-1 b in column-scaled coordinates; columns with no excitation, and those not
    ``fitted`` (a mask; None: all), left out (nan)."""
    p = b.shape[0]
    diag = np.clip(np.diag(R), 0.0, None)
    scale = np.sqrt(diag)
    excited = np.isfinite(scale) & (scale > 1e-9 * max(float(np.max(scale, initial=0.0)), 1e-300))
    if fitted is not None:
        excited &= fitted
    theta = np.full(p, np.nan)
    cov = np.full((p, p), np.nan)
    condition = math.inf
    rss = float(yy)
    idx = np.flatnonzero(excited)
    if idx.size:
        d = scale[idx]
        Rs = R[np.ix_(idx, idx)] / np.outer(d, d)
        bs = b[idx] / d
        if np.all(np.isfinite(Rs)) and np.all(np.isfinite(bs)):
            eig = np.linalg.eigvalsh(Rs)
            condition = math.sqrt(eig[-1] / eig[0]) if eig[0] > 0.0 else math.inf
            ts = np.linalg.lstsq(Rs, bs, rcond=1e-13)[0]
            theta[idx] = ts / d
            cov[np.ix_(idx, idx)] = np.linalg.pinv(Rs, rcond=1e-13, hermitian=True)
            t = theta[idx]
            rss = float(yy - 2.0 * t @ b[idx] + t @ R[np.ix_(idx, idx)] @ t)
    return _Solution(theta, cov, scale, excited, condition, max(rss, 0.0))


def _hac_inflation(phi: np.ndarray, residual: np.ndarray, lags: int) -> np.ndarray:
    """Per column: the Newey-West (Bartlett) variance of the LS estimate over the naive
    s^2 (Phi^T Phi)^-1 one, at least 1 (nan where undefined)."""
    m, p = phi.shape
    if m <= p + 1:
        return np.full(p, np.nan)
    g = phi * residual[:, None]
    meat = g.T @ g
    for lag in range(1, min(lags, m - 1) + 1):
        gamma = g[lag:].T @ g[:-lag]
        meat += (1.0 - lag / (lags + 1.0)) * (gamma + gamma.T)
    gram = phi.T @ phi
    inv = np.linalg.pinv(gram, hermitian=True)
    hac = np.diag(inv @ meat @ inv)
    naive = residual @ residual / (m - p) * np.diag(inv)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(naive > 0.0, hac / naive, np.nan)
    return np.where(np.isfinite(ratio), np.maximum(ratio, 1.0), np.nan)


class _JointInformation:
    """One joint's accumulated (forgotten) information: the base columns' and every reflex
    grid point's."""

    def __init__(self, grid: int, fitted: np.ndarray) -> None:
        p = len(BASE_PARAMETERS)
        self.fitted = fitted
        """Mask of the base columns fitted (the voluntary ones only when asked for)."""
        self.R = np.zeros((p, p))
        self.b = np.zeros(p)
        self.Rxg = np.zeros((grid, p))
        self.Rgg = np.zeros(grid)
        self.bg = np.zeros(grid)
        self.yy = 0.0
        self.samples = 0.0
        self.w1 = 0.0
        self.w2 = 0.0
        self.trials = 0
        self.peak_speed = 0.0
        self.inflation = np.full(p + 1, np.nan)
        self.unresolved = 0.0
        self._rss: np.ndarray | None = None

    def add(self, phi: np.ndarray, reflex: np.ndarray, active: np.ndarray, y: np.ndarray,
            forgetting: float, speed: float, unresolved: float) -> None:
        """One trial's information; ``reflex`` holds the grid points ``active`` (the others'
        columns are zero in this trial)."""
        lam = forgetting
        self.unresolved = max(unresolved, lam * self.unresolved)
        self.R = lam * self.R + phi.T @ phi
        self.b = lam * self.b + phi.T @ y
        self.Rxg *= lam
        self.Rgg *= lam
        self.bg *= lam
        if active.size:
            self.Rxg[active] += reflex.T @ phi
            self.Rgg[active] += np.sum(reflex * reflex, axis=0)
            self.bg[active] += reflex.T @ y
        self.yy = lam * self.yy + float(y @ y)
        self.samples = lam * self.samples + y.shape[0]
        self.w1 = lam * self.w1 + 1.0
        self.w2 = lam * lam * self.w2 + 1.0
        self.trials += 1
        self.peak_speed = max(self.peak_speed, speed)
        self._rss = None

    def grid_rss(self) -> np.ndarray:
        """Residual of the base columns plus each reflex grid point's column (inf where that
        column is not excited)."""
        if self._rss is None:
            self._rss = self._grid_rss()
        return self._rss

    def _grid_rss(self) -> np.ndarray:
        p = self.R.shape[0]
        grid = self.Rgg.shape[0]
        full = np.zeros((grid, p + 1, p + 1))
        full[:, :p, :p] = self.R
        full[:, p, :p] = self.Rxg
        full[:, :p, p] = self.Rxg
        full[:, p, p] = self.Rgg
        rhs = np.concatenate([np.broadcast_to(self.b, (grid, p)), self.bg[:, None]], axis=1)
        unused = np.flatnonzero(~self.fitted)
        full[:, unused, :] = 0.0
        full[:, :, unused] = 0.0
        rhs[:, unused] = 0.0
        d = np.sqrt(np.clip(np.einsum("gii->gi", full), 1e-300, None))
        scaled = full / (d[:, :, None] * d[:, None, :]) + 1e-10 * np.eye(p + 1)
        theta = np.linalg.solve(scaled, (rhs / d)[..., None])[..., 0] / d
        rss = self.yy - np.einsum("gi,gi->g", theta, rhs)
        rss[~np.isfinite(rss)] = np.inf
        rss[self.Rgg <= 1e-12 * max(float(self.R[3, 3]), 1e-300)] = np.inf
        return np.asarray(rss)


class JointForceIdentifier:
    """Identifies the patient's joint forces trial by trial (module docstring): feed every
    trial's measured position and commanded effort to :meth:`update`."""

    def __init__(self, nominal: ArmModel, settings: IdentificationSettings | None = None) -> None:
        self.nominal = nominal
        self.settings = settings or IdentificationSettings()
        self.filters = _Filters(self.settings)
        self.thresholds = np.asarray(self.settings.reflex_thresholds, dtype=float)
        self.delays = self.settings.delay_samples
        grid = len(self.delays) * self.thresholds.shape[0] if self.settings.reflex else 0
        self.fitted = np.array([name in PASSIVE_PARAMETERS or self.settings.voluntary
                                for name in BASE_PARAMETERS])
        self.joints = [_JointInformation(grid, self.fitted) for _ in range(nominal.dof)]
        self.estimate: PatientEstimate | None = None
        """The latest estimate (None before the first trial)."""
        self._trial = 0

    def update_record(self, record: TrialRecord) -> PatientEstimate:
        """:meth:`update` with a trial's record (measured position, commanded effort, its
        reference). An aborted trial is used whole: the arm's dynamics hold through the safe
        hold too (a hold that chatters is refused like any chattering trial)."""
        return self.update(record.position, record.effort, record.trial,
                           (record.reference.position, record.reference.velocity))

    def update(self, position: np.ndarray, effort: np.ndarray, trial: int | None = None,
               reference: tuple[np.ndarray, np.ndarray] | None = None) -> PatientEstimate:
        """Add one trial's samples, (N+1, n) each, and return the estimate after it;
        ``reference``: the (q_d, qdot_d) it tracked (for the patient's own effort). A trial
        whose samples are unusable (wrong shape, non-finite, too short, chatter) changes
        nothing: the estimate says why in ``rejected``."""
        self._trial = int(trial) if trial is not None else self._trial + 1
        q = np.asarray(position, dtype=float)
        u = np.asarray(effort, dtype=float)
        n = self.nominal.dof
        s = self.settings
        minimum = int(round(s.burn_in / s.period)) + 4 * len(BASE_PARAMETERS) + 30
        why = ""
        if q.ndim != 2 or q.shape[1] != n or u.shape != q.shape:
            why = (f"position and effort must both be (samples, {n}), got {q.shape} and "
                   f"{u.shape}")
        elif q.shape[0] < minimum:
            why = f"{q.shape[0]} samples, at least {minimum} are needed"
        elif not (np.all(np.isfinite(q)) and np.all(np.isfinite(u))):
            why = "the samples hold non-finite values"
        elif reference is not None and not (
                np.shape(reference[0]) == q.shape and np.shape(reference[1]) == q.shape
                and np.all(np.isfinite(reference[0])) and np.all(np.isfinite(reference[1]))):
            why = f"the reference must be finite and {q.shape}"
        if why:
            return self._conclude(f"trial {self._trial} not used: {why}")
        reg = trial_regressors(self.nominal, s, q, u, self.filters, reference)
        fast = np.flatnonzero(reg.unresolved > s.max_unresolved_motion)
        if fast.size:
            j = int(fast[np.argmax(reg.unresolved[fast])])
            return self._conclude(
                f"trial {self._trial} not used: joint {j} moved faster than the regression "
                f"resolves ({reg.unresolved[j]:.2g} rad RMS above {s.smoothing_cutoff:g} Hz > "
                f"{s.max_unresolved_motion:g}: chatter or stick-slip), which biases every "
                "joint coupled to it")
        reflexes = []
        for j, info in enumerate(self.joints):
            phi = np.ascontiguousarray(reg.base[:, j, :])
            y = np.ascontiguousarray(reg.target[:, j])
            v = np.ascontiguousarray(reg.velocity[:, j])
            reflex, active = self._reflex(v, reg)
            reflexes.append((reflex, active))
            alone = _solve(phi.T @ phi, phi.T @ y, float(y @ y), self.fitted)
            well = (alone.condition <= s.max_condition and bool(np.all(
                alone.excited[:4])))
            info.add(phi, reflex, active, y, s.forgetting if well else 1.0,
                     float(np.max(np.abs(v))), float(reg.unresolved[j]))
        estimate = self._conclude("")
        for j, info in enumerate(self.joints):
            self._update_inflation(j, info, reg, reflexes[j], estimate.joints[j])
        self.estimate = self._conclude("")
        return self.estimate

    def _reflex(self, velocity: np.ndarray,
                reg: TrialRegressors) -> tuple[np.ndarray, np.ndarray]:
        """The reflex columns of the grid points whose threshold this trial's stretch exceeds
        (the others are zero), and their grid indices."""
        width = self.thresholds.shape[0]
        if not self.settings.reflex:
            return np.zeros((reg.target.shape[0], 0)), np.zeros(0, dtype=int)
        below = np.flatnonzero(self.thresholds < np.max(np.abs(velocity)))
        active = (np.arange(len(self.delays))[:, None] * width + below[None, :]).ravel()
        cols = reflex_columns(velocity, self.thresholds[below], self.delays, self.filters,
                              reg.skip)
        return _project_out(cols, reg.transients), active

    # --- estimation -------------------------------------------------------------------------

    def _conclude(self, rejected: str) -> PatientEstimate:
        joints = tuple(self._joint(j, info) for j, info in enumerate(self.joints))
        estimate = PatientEstimate(self._trial, joints, rejected)
        if rejected:
            self.estimate = estimate
        return estimate

    def _selected(self, info: _JointInformation) -> tuple[int | None, _Solution, _Solution]:
        """The best reflex grid point (None: no reflex column), its solution, the base one."""
        base = _solve(info.R, info.b, info.yy, info.fitted)
        if info.Rgg.shape[0] == 0 or info.trials == 0:
            return None, base, base
        rss = info.grid_rss()
        best = int(np.argmin(rss))
        if not np.isfinite(rss[best]):
            return None, base, base
        p = info.R.shape[0]
        R = np.zeros((p + 1, p + 1))
        R[:p, :p] = info.R
        R[p, :p] = R[:p, p] = info.Rxg[best]
        R[p, p] = info.Rgg[best]
        b = np.append(info.b, info.bg[best])
        return best, _solve(R, b, info.yy, np.append(info.fitted, True)), base

    def _update_inflation(self, j: int, info: _JointInformation, reg: TrialRegressors,
                          reflex: tuple[np.ndarray, np.ndarray],
                          estimate: JointEstimate) -> None:
        """The autocorrelation inflation of the variances, from this trial's residual under
        the model now reported (lambda-weighted mean over trials)."""
        best, chosen, _ = self._selected(info)
        phi = reg.base[:, j, :]
        p = phi.shape[1]
        if estimate.reflex_detected and best is not None:
            columns, active = reflex
            where = np.flatnonzero(active == best)
            col = columns[:, where[0]] if where.size else np.zeros(phi.shape[0])
            phi = np.column_stack([phi, col])
            theta = chosen.theta
        else:
            theta = _solve(info.R, info.b, info.yy, info.fitted).theta
        use = np.isfinite(theta)
        if not np.any(use):
            return
        residual = reg.target[:, j] - phi[:, use] @ theta[use]
        lags = int(math.ceil(4.0 / (self.settings.filter_bandwidth * self.settings.period)))
        new = np.full(p + 1, np.nan)
        new[np.flatnonzero(use)] = _hac_inflation(phi[:, use], residual, lags)
        lam = self.settings.forgetting
        old = info.inflation
        weight_old = lam * (info.w1 - 1.0)
        mixed = np.where(np.isfinite(old), (weight_old * old + new) / (weight_old + 1.0), new)
        info.inflation = np.where(np.isfinite(mixed), mixed, old)

    def _joint(self, j: int, info: _JointInformation) -> JointEstimate:
        s = self.settings
        if info.trials == 0:
            empty = {name: ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan,
                                             False, False, "no trial yet")
                     for name in PARAMETERS}
            return JointEstimate(j, empty, False, math.inf, math.nan, 0.0, 0, False,
                                 ("no trial yet",))
        best, with_reflex, base = self._selected(info)
        p = len(BASE_PARAMETERS)
        detected = False
        reflex_reason = ""
        if not s.reflex:
            reflex_reason = "reflex not identified (settings)"
        elif best is None:
            reflex_reason = (f"not identifiable: the stretch velocity ({info.peak_speed:.3g} "
                             f"rad/s) never exceeded a threshold of the grid "
                             f"(>= {self.thresholds[0]:.3g} rad/s)")
        else:
            reflex_reason = self._reflex_rejection(info, best, with_reflex, base)
            detected = not reflex_reason
        chosen = with_reflex if detected else base
        sigma2 = chosen.rss / max(info.samples - int(np.sum(chosen.excited)), 1.0)
        weights = info.w2 / info.w1
        inflation = info.inflation[:chosen.theta.shape[0]]
        inflation = np.where(np.isfinite(inflation), inflation, 1.0)
        scale = np.where(chosen.excited, chosen.scale, np.nan)
        cov = sigma2 * weights * chosen.covariance_scaled / np.outer(scale, scale)
        cov = cov * np.sqrt(np.outer(inflation, inflation))
        vif = np.diag(chosen.covariance_scaled)
        theta = chosen.theta
        params: dict[str, ParameterEstimate] = {}
        names = (*BASE_PARAMETERS, "reflex_gain") if detected else BASE_PARAMETERS
        for k, name in enumerate(names):
            if name == "model_scale" and not s.model_scale:
                params[name] = ParameterEstimate(name, 0.0, 0.0, 0.0, 0.0, True, True,
                                                 "")
                continue
            if name.startswith("voluntary") and not s.voluntary:
                params[name] = ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan,
                                                 False, False, "not fitted (voluntary=False)")
                continue
            params[name] = self._parameter(name, theta[k], cov[k, k], chosen.excited[k],
                                           vif[k], chosen.covariance_scaled, k, names)
        params["rest_position"] = self._rest_position(theta, cov, params)
        if detected and best is not None:
            params.update(self._reflex_grid(info, best, sigma2 * weights
                                            * float(inflation[p])))
        else:
            upper = math.nan
            if best is not None:
                g, se = self._stats(info, with_reflex, p)
                upper = max(g + _Z95 * se, 0.0) if math.isfinite(g + se) else math.nan
            identifiable = not reflex_reason.startswith("not identifiable")
            params["reflex_gain"] = ParameterEstimate("reflex_gain", 0.0, math.nan, 0.0, upper,
                                                      identifiable, False, reflex_reason)
            for name in ("reflex_threshold", "reflex_delay"):
                params[name] = ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan,
                                                 False, False, reflex_reason)
        needed = list(PASSIVE_PARAMETERS)
        if detected:
            needed += ["reflex_gain", "reflex_threshold", "reflex_delay"]
        reasons = [f"{name}: {params[name].reason}" for name in needed
                   if not params[name].trustworthy]
        if not math.isfinite(chosen.condition) or chosen.condition > s.max_condition:
            reasons.insert(0, f"condition number {chosen.condition:.3g} > {s.max_condition:g}")
        suspicion = self._voluntary_suspicion(info, best if detected else None, chosen,
                                              sigma2)
        if suspicion:
            reasons.insert(0, suspicion)
        if info.unresolved > s.max_unresolved_motion:
            reasons.insert(0, f"the joint moved faster than the regression resolves "
                              f"({info.unresolved:.2g} rad RMS above {s.smoothing_cutoff:g} Hz "
                              f"> {s.max_unresolved_motion:g}: chatter or stick-slip)")
        rms = math.sqrt(chosen.rss / info.samples) if info.samples > 0 else math.nan
        return JointEstimate(j, params, detected, chosen.condition, rms, info.peak_speed,
                             info.trials, not reasons, tuple(reasons))

    def _voluntary_suspicion(self, info: _JointInformation, best: int | None,
                             chosen: _Solution, sigma2: float) -> str:
        """"" unless the voluntary columns are not fitted, yet would lower the residual
        significantly (chi^2_2(0.999) = 13.8, with the passive columns' autocorrelation
        inflation) and by more than ``voluntary_minimum_torque``: then a patient's own effort
        is likely in the passive estimate."""
        p = len(BASE_PARAMETERS)
        if self.settings.voluntary or info.trials == 0:
            return ""
        voluntary = ~info.fitted
        if not np.all(np.diag(info.R)[voluntary] > 0.0):
            return ""  # no reference given
        R, b = info.R, info.b
        mask = np.ones(p, dtype=bool)
        if best is not None:
            R = np.zeros((p + 1, p + 1))
            R[:p, :p] = info.R
            R[p, :p] = R[:p, p] = info.Rxg[best]
            R[p, p] = info.Rgg[best]
            b = np.append(info.b, info.bg[best])
            mask = np.append(mask, True)
        full = _solve(R, b, info.yy, mask)
        inflation = info.inflation[:len(PASSIVE_PARAMETERS)]
        infl = float(np.nanmedian(inflation)) if np.any(np.isfinite(inflation)) else 1.0
        scale = sigma2 * max(infl, 1.0) * info.w2 / info.w1
        drop = (chosen.rss - full.rss) / scale if scale > 0.0 else 0.0
        explained = math.sqrt(max(chosen.rss - full.rss, 0.0) / max(info.samples, 1.0))
        if drop > 13.8 and explained > self.settings.voluntary_minimum_torque:
            return (f"the tracking error explains {explained:.2g} N m RMS of the residual, "
                    f"{drop:.3g} times chance (chi^2_2(0.999) = 13.8): the patient's own effort "
                    "is likely in the estimate (identify with voluntary=True, or on relaxed "
                    "trials)")
        return ""

    def _reflex_rejection(self, info: _JointInformation, best: int, with_reflex: _Solution,
                          base: _Solution) -> str:
        """"" if the reflex at grid point ``best`` is detected, else why not: G excited, not
        collinear, its interval above 0, its torque at the fastest stretch above the minimum,
        the residual's drop significant (chi^2_3(0.999) = 16.3: G, v_th and tau_r are fitted)
        and v_th above the grid's lowest value (a reflex from zero speed on is damping)."""
        s = self.settings
        p = len(BASE_PARAMETERS)
        g, se = self._stats(info, with_reflex, p)
        threshold = float(self.thresholds[best % self.thresholds.shape[0]])
        torque = g * max(info.peak_speed - threshold, 0.0)
        vif = float(with_reflex.covariance_scaled[p, p])
        if not (math.isfinite(g) and math.isfinite(se)):
            return "not identifiable: the reflex column is not excited"
        if not vif <= s.max_variance_inflation:
            names = (*BASE_PARAMETERS, "reflex_gain")
            return (f"no reflex detected: G not identifiable (variance inflation {vif:.3g}, "
                    f"collinear with {_most_correlated(with_reflex.covariance_scaled, p, names)})")
        if g - _Z95 * se <= 0.0:
            return f"no reflex detected: G = {g:.3g} +- {_Z95 * se:.2g} N m s/rad includes 0"
        if torque < s.reflex_minimum_torque:
            return (f"no reflex detected: its torque at the fastest stretch ({torque:.3g} N m) "
                    f"is below {s.reflex_minimum_torque} N m")
        sigma2 = with_reflex.rss / max(info.samples - p - 1, 1.0)
        infl = info.inflation[p] if math.isfinite(info.inflation[p]) else 1.0
        drop = (base.rss - with_reflex.rss) / (sigma2 * infl * info.w2 / info.w1)
        if not drop > 16.3:
            return (f"no reflex detected: it lowers the residual by only {drop:.3g} "
                    "(chi^2_3(0.999) = 16.3)")
        grid = self._reflex_grid(info, best, sigma2 * infl * info.w2 / info.w1)
        if grid["reflex_threshold"].low <= self.thresholds[0]:
            return (f"no reflex detected: its threshold (v_th <= "
                    f"{grid['reflex_threshold'].high:.3g} rad/s) is not distinguishable from "
                    f"{self.thresholds[0]:g} rad/s (a reflex from rest on is damping)")
        return ""

    def _stats(self, info: _JointInformation, solution: _Solution, k: int) -> tuple[float, float]:
        """Value and standard error of column ``k`` of ``solution``."""
        sigma2 = solution.rss / max(info.samples - int(np.sum(solution.excited)), 1.0)
        infl = info.inflation[k] if math.isfinite(info.inflation[k]) else 1.0
        var = (sigma2 * info.w2 / info.w1 * solution.covariance_scaled[k, k]
               / solution.scale[k] ** 2 * infl)
        return float(solution.theta[k]), math.sqrt(var) if var >= 0.0 else math.nan

    def _parameter(self, name: str, value: float, variance: float, excited: bool, vif: float,
                   cov_scaled: np.ndarray, k: int, names: tuple[str, ...]) -> ParameterEstimate:
        s = self.settings
        se = math.sqrt(variance) if variance >= 0.0 else math.nan
        if not excited:
            return ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan, False, False,
                                     "not identifiable: its regressor is zero (not excited)")
        identifiable = math.isfinite(vif) and vif <= s.max_variance_inflation
        reason = ""
        if not identifiable:
            reason = (f"not identifiable: variance inflation {vif:.3g} > "
                      f"{s.max_variance_inflation:g}, collinear with "
                      f"{_most_correlated(cov_scaled, k, names)}")
        reason = reason or _judge(name, value, se, s)
        return ParameterEstimate(name, value, se, value - _Z95 * se, value + _Z95 * se,
                                 identifiable, not reason, reason)

    def _rest_position(self, theta: np.ndarray, cov: np.ndarray,
                       params: Mapping[str, ParameterEstimate]) -> ParameterEstimate:
        """q_0 = -c / K, its variance by the delta method."""
        k, c = theta[2], theta[3]
        stiffness = params["stiffness"]
        offset = params["offset"]
        if not (stiffness.identifiable and offset.identifiable):
            return ParameterEstimate("rest_position", math.nan, math.nan, math.nan, math.nan,
                                     False, False, "not identifiable: stiffness or offset is not")
        if not (stiffness.low > 0.0):
            return ParameterEstimate("rest_position", math.nan, math.nan, math.nan, math.nan,
                                     False, False, "not identifiable: no significant stiffness "
                                     "to define a rest position")
        q0 = -c / k
        grad = np.array([c / k ** 2, -1.0 / k])
        sub = cov[np.ix_([2, 3], [2, 3])]
        var = float(grad @ sub @ grad)
        se = math.sqrt(var) if var >= 0.0 else math.nan
        reason = _judge("rest_position", q0, se, self.settings)
        return ParameterEstimate("rest_position", q0, se, q0 - _Z95 * se, q0 + _Z95 * se,
                                 True, not reason, reason)

    def _reflex_grid(self, info: _JointInformation, best: int,
                     variance_scale: float) -> dict[str, ParameterEstimate]:
        """v_th and tau_r with intervals from the residual's profile: the grid points within
        chi^2_1(0.95) = 3.84 (scaled residual variance) of the least residual."""
        rss = info.grid_rss().reshape(len(self.delays), self.thresholds.shape[0])
        di, ti = divmod(best, self.thresholds.shape[0])
        limit = rss[di, ti] + 3.84 * variance_scale
        th_in = self.thresholds[rss[di] <= limit]
        delays = np.asarray(self.delays, dtype=float) * self.settings.period
        de_in = delays[rss[:, ti] <= limit]
        out = {}
        for name, value, inside, grid in (("reflex_threshold", self.thresholds[ti], th_in,
                                           self.thresholds),
                                          ("reflex_delay", delays[di], de_in, delays)):
            low, high = float(np.min(inside)), float(np.max(inside))
            at_edge = low <= grid[0] or high >= grid[-1]
            reason = ("its interval reaches the grid's edge (not determined)"
                      if at_edge and grid.shape[0] > 1 else "")
            out[name] = ParameterEstimate(name, float(value), (high - low) / (2 * _Z95), low,
                                          high, not reason, not reason, reason)
        return out


def _most_correlated(cov_scaled: np.ndarray, k: int, names: tuple[str, ...]) -> str:
    """The parameter whose estimate correlates most with parameter ``k``'s."""
    c = cov_scaled
    d = np.sqrt(np.abs(np.diag(c)))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = c[k] / (d[k] * d)
    corr = np.where(np.isfinite(corr), np.abs(corr), -1.0)
    corr[k] = -1.0
    other = int(np.argmax(corr[:len(names)]))
    return f"{names[other]} (correlation {corr[other]:.3f})"


def _judge(name: str, value: float, se: float, s: IdentificationSettings) -> str:
    """"" if a parameter's estimate is usable, else why not."""
    if not (math.isfinite(value) and math.isfinite(se)):
        return "non-finite estimate"
    if name in s.bounds:
        low, high = s.bounds[name]
        margin = max(3.0 * se, s.absolute_precision.get(name, 0.0))
        if value < low - margin or value > high + margin:
            return (f"absurd: {value:.4g} outside [{low:g}, {high:g}] by more than "
                    f"{margin:.2g} (3 SE, or the precision floor)")
    half = _Z95 * se
    tolerance = max(s.relative_precision * abs(value), s.absolute_precision.get(name, 0.0))
    if half > tolerance:
        return f"imprecise: 95 % half-width {half:.3g} > {tolerance:.3g}"
    return ""


@dataclass(frozen=True, eq=False)
class JointForceTerm:
    """The identified joint forces computed torque would add (:func:`joint_force_term`)."""

    torque: np.ndarray
    """(samples, n) N m: tau_p along the given states, 0 on a joint not used, clamped."""
    used: np.ndarray
    """(n,) bool: the joint's estimate was trustworthy and is in ``torque``."""
    reasons: tuple[str, ...]
    """Per joint: why it is not used ("" when it is)."""
    clamped: np.ndarray
    """(n,) int: samples where the limit clamped the joint's term."""


def joint_force_term(estimate: PatientEstimate, position: np.ndarray, velocity: np.ndarray,
                     limit: np.ndarray | float, settings: IdentificationSettings | None = None
                     ) -> JointForceTerm:
    """tau_p = B qdot + F_c tanh(qdot / v_s) + K (q - q_0) + G sgn(v) max(0, abs(v) - v_th),
    v = qdot(t - tau_r) (the first value before the start), the term eq (6)'s Q^v, Q^f, Q^c
    and the reflex add to computed torque, eqs (9)/(16): Q = a_N(q) u + c_N(q, qdot) + tau_p,
    along the (samples, n) ``position`` and ``velocity`` (the reference's, so that no measured
    velocity is fed back). Only a trustworthy joint's estimate is used (the reflex only when
    detected), each parameter inside its plausible range, the term clamped to +-``limit``
    (N m, per joint); any other joint adds 0 and says why."""
    s = settings or IdentificationSettings()
    q = np.asarray(position, dtype=float)
    qd = np.asarray(velocity, dtype=float)
    n = len(estimate.joints)
    if q.ndim != 2 or q.shape[1] != n or qd.shape != q.shape:
        raise ValueError(f"position and velocity must both be (samples, {n}), got {q.shape} "
                         f"and {qd.shape}")
    bound = np.broadcast_to(np.asarray(limit, dtype=float), (n,))
    torque = np.zeros(q.shape)
    used = np.zeros(n, dtype=bool)
    clamped = np.zeros(n, dtype=int)
    reasons = []
    for j, joint in enumerate(estimate.joints):
        names = ["viscous", "coulomb", "stiffness", "rest_position"]
        if joint.reflex_detected:
            names += ["reflex_gain", "reflex_threshold", "reflex_delay"]
        values = {name: joint.value(name) for name in names}
        why = ""
        if not joint.trustworthy:
            why = "; ".join(joint.reasons) or "not trustworthy"
        elif not all(math.isfinite(v) for v in values.values()):
            why = "non-finite estimate"
        elif not (np.all(np.isfinite(q[:, j])) and np.all(np.isfinite(qd[:, j]))
                  and math.isfinite(float(bound[j])) and bound[j] >= 0.0):
            why = "non-finite states or limit"
        if why:
            reasons.append(why)
            continue
        for name, value in values.items():
            if name in s.bounds:
                low, high = s.bounds[name]
                values[name] = min(max(value, low), high)
        v = qd[:, j]
        term = (values["viscous"] * v
                + values["coulomb"] * np.tanh(v / s.stribeck_velocity)
                + values["stiffness"] * (q[:, j] - values["rest_position"]))
        if joint.reflex_detected:
            delay = int(round(values["reflex_delay"] / s.period))
            delayed = np.concatenate([np.repeat(v[:1], delay), v[:v.shape[0] - delay]]) \
                if delay > 0 else v
            excess = np.maximum(np.abs(delayed) - values["reflex_threshold"], 0.0)
            term = term + values["reflex_gain"] * np.sign(delayed) * excess
        clamped[j] = int(np.sum(np.abs(term) > bound[j]))
        torque[:, j] = np.clip(term, -bound[j], bound[j])
        used[j] = True
        reasons.append("")
    return JointForceTerm(torque, used, tuple(reasons), clamped)
