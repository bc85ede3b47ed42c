"""Is the learned input still growing? A log-linear fit of max |u_ff| over the last trials.

A learning law whose trial-to-trial factor exceeds 1 somewhere (:mod:`.convergence`) grows the
learned input geometrically in that band, max |u_ff|_k ~ c rho^k, long before the tracking error
shows it. Fitting log max |u_ff| = a + r k over the last ``window`` trials estimates r = log rho
per trial; a run is flagged when r is both above a practical floor and significantly above 0,
the trial-to-trial increments of max |u_ff| are not shrinking, and log max |u_ff| drifts
upward significantly from trial to trial. A learned input that still approaches its limit
(increments falling geometrically, as a converging law's do in its first tens of trials) also
has r > 0 over a short window, but it is not growing: flagging it was the false ``GROWING`` of
norm_optimal at 30 trials (issue 25).

The drift test (:func:`drift_significant`) is there because the fit's standard error assumes
independent residuals about the line, and a converged learned input's are not: the law
integrates whatever of the error does not repeat (an encoder's noise), and the identified
patient forces it hands over move it in steps, so from trial to trial max |u_ff| wanders like
a random walk about its level. A straight line fitted to a random walk finds a "significant"
slope far more often than its nominal rate (the spurious trend of a unit-root series: Nelson
and Kang 1981, J Am Stat Assoc 76:741; Phillips 1986, J Econometrics 33:311); the test of a
drift that holds under a random walk is the t-test on the mean of its increments. Geometric
growth rho^k is a random walk with drift log rho, so it still passes it, with a t that grows as
the noise falls (an exact rho^k: every increment log rho). This is the false ``GROWING`` of a
UR5 patient with a 14-bit encoder (issue 33: a flat, small learned input that stepped up 6 %
and 19 % on two joints at one trial of 25; fitted rates 0.006 and 0.017 a trial at 5 and 3.5
standard errors, drift t 0.9 and 1.1).
Works on any (trials, joints) table: an in-process run, a JSON export or a bag's trials.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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
    usable: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    """Per joint: trials of the window with a learned input (max |u_ff| > 0); fewer than
    :data:`MIN_TRIALS` give no rate (NaN), none means the joint learned nothing."""
    converging: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    """Per joint: the increments of max |u_ff| shrink significantly (approach to a limit)."""
    drift_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Per joint: the t statistic of the mean increment of log max |u_ff| over the window
    (:func:`drift_significant`; NaN where there is no rate)."""

    @property
    def any_growing(self) -> bool:
        """True if some joint's learned input keeps growing."""
        return bool(np.any(self.growing))

    def factor(self) -> np.ndarray:
        """exp(r): the measured trial-to-trial factor of max |u_ff| per joint."""
        return np.asarray(np.exp(self.rate))


def _slope(k: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of y against k and its standard error (compensated sums: the same
    bits whatever BLAS the machine has)."""
    kc = k - k.mean()
    sxx = math.fsum(kc * kc)
    slope = math.fsum(kc * (y - y.mean())) / sxx
    residual = y - y.mean() - kc * slope
    return slope, math.sqrt(math.fsum(residual * residual) / (k.size - 2) / sxx)


def increments_shrink(column: np.ndarray, significance: float = DEFAULT_SIGNIFICANCE) -> bool:
    """True if the trial-to-trial changes of ``column`` (max |u_ff| of one joint) fall
    geometrically: the slope of log |u_(k+1) - u_k| is significantly below 0. Changes at the
    rounding level of the values (below :data:`INCREMENT_FLOOR` of them) carry no trend and
    are left out; too few left: False."""
    change = np.abs(np.diff(column))
    used = change > INCREMENT_FLOOR * np.abs(column[1:])
    if np.count_nonzero(used) < MIN_TRIALS - 1:
        return False
    slope, stderr = _slope(np.flatnonzero(used).astype(float), np.log(change[used]))
    return bool(slope < 0.0 and slope < -significance * stderr)


INCREMENT_FLOOR = 1e-9
"""Relative size below which a change of max |u_ff| is rounding, not learning."""


def drift_t(column: np.ndarray) -> float:
    """The t statistic of the mean trial-to-trial increment of log ``column`` (max |u_ff| of
    one joint, every entry > 0): mean / (sd / sqrt(m)) over its m increments; +inf for a
    positive mean with no spread (exact geometric growth), NaN for fewer than 2 increments."""
    d = np.diff(np.log(np.asarray(column, dtype=float)))
    if d.size < 2:
        return math.nan
    mean = math.fsum(d) / d.size
    spread = math.sqrt(math.fsum((d - mean) ** 2) / (d.size - 1))
    if spread <= 1e-12 * max(abs(mean), 1e-300):
        return math.inf if mean > 0.0 else (0.0 if mean == 0.0 else -math.inf)
    return mean / (spread / math.sqrt(d.size))


def drift_significant(column: np.ndarray, significance: float = DEFAULT_SIGNIFICANCE) -> bool:
    """True if log ``column`` drifts upward from trial to trial significantly: the mean of its
    increments is more than ``significance`` standard errors above 0 (:func:`drift_t`; the
    drift test of a random walk, module docstring)."""
    t = drift_t(column)
    return bool((math.isfinite(t) and t > significance) or t == math.inf)


def fit_growth(max_abs_feedforward: np.ndarray, window: int = DEFAULT_WINDOW,
               min_rate: float = DEFAULT_MIN_RATE,
               significance: float = DEFAULT_SIGNIFICANCE) -> GrowthFit | None:
    """Least-squares fit of log max |u_ff|_k = a + r k per joint over the last ``window`` trials.

    Flags a joint when r > ``min_rate`` and r > ``significance`` * stderr(r) (ordinary least
    squares standard error) and log max |u_ff| drifts upward significantly from trial to trial
    (:func:`drift_significant`: not a random walk's spurious trend), unless its increments
    shrink (:func:`increments_shrink`: still approaching a limit). Zero entries (trial 1's zero
    feed-forward) are left out; a joint with fewer than :data:`MIN_TRIALS` usable trials gets
    NaN and no flag. None if the table has fewer than :data:`MIN_TRIALS` trials.
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
    usable = np.zeros(joints, dtype=int)
    converging = np.zeros(joints, dtype=bool)
    drift = np.full(joints, np.nan)
    for j in range(joints):
        column = table[first:, j]
        used = column > 0.0  # a zero feed-forward (trial 1) has no logarithm
        usable[j] = np.count_nonzero(used)
        if usable[j] < MIN_TRIALS:
            continue
        k = np.arange(first, table.shape[0], dtype=float)[used]
        rate[j], stderr[j] = _slope(k, np.log(column[used]))
        converging[j] = increments_shrink(column[used], significance)
        drift[j] = drift_t(column[used])
    with np.errstate(invalid="ignore"):
        drifting = (drift > significance) | (drift == math.inf)
        growing = (rate > min_rate) & (rate > significance * stderr) & drifting & ~converging
    return GrowthFit(rate, stderr, growing, first + 1, table.shape[0], usable, converging,
                     drift)


AT_LIMIT_TOLERANCE = 1e-9
"""Relative distance below ``feedforward_limit`` at which a joint's max |u_ff| is at its limit."""


def held_at_limit(max_abs_feedforward: np.ndarray, limit: np.ndarray | None) -> np.ndarray:
    """Per joint: the last trial's max |u_ff| is at ``limit`` (``feedforward_limit``, inf or
    None: no limit). Such a joint's learned input does not grow because the limit holds it
    (sat_U), not because learning converged: its growth fit says nothing, and a report calls it
    "at its limit", never "bounded"."""
    table = np.asarray(max_abs_feedforward, dtype=float)
    if limit is None or table.ndim != 2 or table.shape[0] == 0:
        return np.zeros(table.shape[-1] if table.ndim == 2 else 0, dtype=bool)
    bound = np.broadcast_to(np.asarray(limit, dtype=float), table.shape[1:])
    with np.errstate(invalid="ignore"):
        return np.asarray(np.isfinite(bound) & (table[-1] >= bound * (1.0 - AT_LIMIT_TOLERANCE)))
