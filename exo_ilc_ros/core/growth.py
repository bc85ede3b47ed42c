"""Is the learned input still growing? A log-linear fit of max |u_ff| over the last trials.

A learning law whose trial-to-trial factor exceeds 1 somewhere (:mod:`.convergence`) grows the
learned input geometrically in that band, max |u_ff|_k ~ c rho^k, long before the tracking error
shows it. Fitting log max |u_ff| = a + r k over the last ``window`` trials estimates r = log rho
per trial; a run is flagged when r is both above a practical floor and significantly above 0.
Works on any (trials, joints) table: an in-process run, a JSON export or a bag's trials.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEFAULT_WINDOW = 100
"""Trials fitted (the last ones); fewer if the run is shorter."""
DEFAULT_MIN_RATE = 1e-3
"""Growth per trial below which a run is not flagged (1e-3: x2.7 over 1000 trials)."""
DEFAULT_SIGNIFICANCE = 3.0
"""The fitted rate must exceed this many standard errors."""
MIN_TRIALS = 10
"""Fewer trials than this give no verdict."""


@dataclass(frozen=True)
class GrowthFit:
    """Per joint: fitted growth rate r of log max |u_ff| per trial, its standard error, and the
    verdict. ``first_trial``..``last_trial`` (1-based) is the fitted window."""

    rate: np.ndarray
    stderr: np.ndarray
    growing: np.ndarray
    first_trial: int
    last_trial: int

    @property
    def any_growing(self) -> bool:
        """True if some joint's learned input keeps growing."""
        return bool(np.any(self.growing))

    def factor(self) -> np.ndarray:
        """exp(r): the measured trial-to-trial factor of max |u_ff| per joint."""
        return np.asarray(np.exp(self.rate))


def fit_growth(max_abs_feedforward: np.ndarray, window: int = DEFAULT_WINDOW,
               min_rate: float = DEFAULT_MIN_RATE,
               significance: float = DEFAULT_SIGNIFICANCE) -> GrowthFit | None:
    """Least-squares fit of log max |u_ff|_k = a + r k per joint over the last ``window`` trials.

    Flags a joint when r > ``min_rate`` and r > ``significance`` * stderr(r) (ordinary least
    squares standard error). Zero entries (trial 1's zero feed-forward) are left out; a joint
    with fewer than :data:`MIN_TRIALS` usable trials gets NaN and no flag. None if the table has
    fewer than :data:`MIN_TRIALS` trials.
    """
    table = np.asarray(max_abs_feedforward, dtype=float)
    if table.ndim != 2:
        raise ValueError(f"expected a (trials, joints) table, got shape {table.shape}")
    count = min(int(window), table.shape[0])
    if count < MIN_TRIALS:
        return None
    first = table.shape[0] - count
    joints = table.shape[1]
    rate = np.full(joints, np.nan)
    stderr = np.full(joints, np.nan)
    for j in range(joints):
        column = table[first:, j]
        used = column > 0.0  # a zero feed-forward (trial 1) has no logarithm
        if np.count_nonzero(used) < MIN_TRIALS:
            continue
        k = np.arange(first, table.shape[0], dtype=float)[used]
        y = np.log(column[used])
        kc = k - k.mean()
        sxx = math.fsum(kc * kc)
        rate[j] = math.fsum(kc * (y - y.mean())) / sxx
        residual = y - y.mean() - kc * rate[j]
        stderr[j] = np.sqrt(math.fsum(residual * residual) / (k.size - 2) / sxx)
    with np.errstate(invalid="ignore"):
        growing = (rate > min_rate) & (rate > significance * stderr)
    return GrowthFit(rate, stderr, growing, first + 1, table.shape[0])
