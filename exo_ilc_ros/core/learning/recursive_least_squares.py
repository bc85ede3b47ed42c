"""The least squares of the identification of the patient's joint forces
(:mod:`.identification`): a solve in column-scaled coordinates, the autocorrelation-robust
variance inflation, what the choice of one term's law moves the estimate by, and one joint's
information, recursive over trials with forgetting, for the base columns and every reflex grid
point."""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from .identification_settings import BASE_PARAMETERS

_T = TypeVar("_T")


@dataclass
class Solution:
    theta: np.ndarray
    """Per column (nan where not excited)."""
    covariance_scaled: np.ndarray
    """pinv of the column-scaled information of the excited columns, full size (nan rows)."""
    scale: np.ndarray
    excited: np.ndarray
    condition: float
    rss: float


def _scaled(R: np.ndarray, b: np.ndarray, fitted: np.ndarray | None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, float]:
    """R's column scale, the columns solved for (excited and ``fitted``), their indices, the
    scaled information of those (None: none, or not finite) and its condition number."""
    diag = np.clip(np.diag(R), 0.0, None)
    scale = np.sqrt(diag)
    excited = np.isfinite(scale) & (scale > 1e-9 * max(float(np.max(scale, initial=0.0)), 1e-300))
    if fitted is not None:
        excited &= fitted
    idx = np.flatnonzero(excited)
    if not idx.size:
        return scale, excited, idx, None, math.inf
    d = scale[idx]
    Rs = R[np.ix_(idx, idx)] / np.outer(d, d)
    if not (np.all(np.isfinite(Rs)) and np.all(np.isfinite(b[idx] / d))):
        return scale, excited, idx, None, math.inf
    eig = np.linalg.eigvalsh(Rs)
    return scale, excited, idx, Rs, math.sqrt(eig[-1] / eig[0]) if eig[0] > 0.0 else math.inf


def conditioning(R: np.ndarray, b: np.ndarray,
                 fitted: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """:func:`solve_scaled`'s condition number and excited columns alone (no solve)."""
    _, excited, _, _, condition = _scaled(R, b, fitted)
    return condition, excited


def solve_scaled(R: np.ndarray, b: np.ndarray, yy: float,
           fitted: np.ndarray | None = None) -> Solution:
    """theta = R^-1 b in column-scaled coordinates; columns with no excitation, and those not
    ``fitted`` (a mask; None: all), left out (nan)."""
    p = b.shape[0]
    scale, excited, idx, Rs, condition = _scaled(R, b, fitted)
    theta = np.full(p, np.nan)
    cov = np.full((p, p), np.nan)
    rss = float(yy)
    if Rs is not None:
        d = scale[idx]
        ts = np.linalg.lstsq(Rs, b[idx] / d, rcond=1e-13)[0]
        theta[idx] = ts / d
        cov[np.ix_(idx, idx)] = np.linalg.pinv(Rs, rcond=1e-13, hermitian=True)
        t = theta[idx]
        rss = float(yy - 2.0 * t @ b[idx] + t @ R[np.ix_(idx, idx)] @ t)
    return Solution(theta, cov, scale, excited, condition, max(rss, 0.0))


def hac_inflation(phi: np.ndarray, residual: np.ndarray, lags: int) -> np.ndarray:
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


def law_difference(phi: np.ndarray, target: np.ndarray, column: int,
                   alternative: np.ndarray) -> np.ndarray:
    """Per column of ``phi``: the least-squares estimate with column ``column`` replaced by
    ``alternative`` (the same term under another law) minus the estimate with it, on the same
    samples: what not knowing which of the two laws holds moves each parameter by (a model
    error, which more samples do not shrink); nan where the fit fails."""
    other = phi.copy()
    other[:, column] = alternative
    try:
        return np.asarray(np.linalg.lstsq(other, target, rcond=None)[0]
                          - np.linalg.lstsq(phi, target, rcond=None)[0])
    except np.linalg.LinAlgError:  # the SVD did not converge: unknown
        return np.full(phi.shape[1], np.nan)


class JointInformation:
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
        self.fastest = np.zeros(2)
        """rad/s: the fastest qdot > 0 and -qdot of every trial so far (a reversal)."""
        self.inflation = np.full(p + 1, np.nan)
        self.model_covariance = np.zeros((p + 1, p + 1))
        """The friction law's model error, d d^T with d the hard-law fit minus the model's
        (:func:`law_difference`; lambda-weighted mean over trials)."""
        self.unresolved = 0.0
        self._rss: np.ndarray | None = None
        self._derived: dict[Hashable, Any] = {}

    def add(self, phi: np.ndarray, reflex: np.ndarray, active: np.ndarray, y: np.ndarray,
            forgetting: float, velocity: np.ndarray, unresolved: float) -> None:
        """One trial's information; ``reflex`` holds the grid points ``active`` (the others'
        columns are zero in this trial); ``velocity``: the joint's over the trial."""
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
        self.peak_speed = max(self.peak_speed, float(np.max(np.abs(velocity))))
        self.fastest = np.maximum(self.fastest, [max(float(np.max(velocity)), 0.0),
                                                 max(float(-np.min(velocity)), 0.0)])
        self._rss = None
        self._derived.clear()

    def derived(self, key: Hashable, compute: Callable[[], _T]) -> _T:
        """``compute()``, kept under ``key`` until the next :meth:`add`: what the identifier
        derives from this information (a solve, a separation) is asked for several times per
        trial and depends on nothing else. The result is shared: callers must not change it."""
        if key not in self._derived:
            self._derived[key] = compute()
        return self._derived[key]

    def solve(self, mask: np.ndarray) -> Solution:
        """:func:`solve_scaled` of the base columns of ``mask`` (kept until the next trial)."""
        return self.derived(("solve", mask.tobytes()),
                            lambda: solve_scaled(self.R, self.b, self.yy, mask.copy()))

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
