"""A learning gain from the trials' own statistics: the law averages over trials where what is
left of the error does not repeat (not in the paper; issue 28's "a learning gain that backs off
at a non-repeating floor detected from the data").

The plain law sets the next feed-forward to its target T_k (the Q-filtered update of trial k,
plus the inverse with the patient when the identified forces are in the loop). Read T_k as a
noisy measurement of what the arm needs, the local-level model of the trial domain:

    T_k = x_k + n_k,   x_k+1 = x_k + w_k,   n_k white (variance r), w_k white (variance q),   (LL)

x_k the repeating part (it drifts: fatigue, the identified forces, the mass error being learned),
n_k the non-repeating part (the patient's own variation, the sensors' noise, carried into T_k by
the law's deadbeat-like step). The law that minimises the next trial's expected error under
(LL) is the steady-state Kalman filter, an exponential average of the targets:

    u_ff,k+1 = u_ff,k + K (T_k - u_ff,k),   K = (-s + sqrt(s^2 + 4 s)) / 2,   s = q / r,     (KG)

K = 1 the plain law (n = 0: nothing to average), K -> 0 an ever longer average (w = 0). s is
read from the data: the change of the target dT_k = T_k - T_k-1 = w_k-1 + n_k - n_k-1 has the
lag-1 autocorrelation

    rho = E[dT_k dT_k-1] / E[dT_k^2] = -r / (q + 2 r),   so s = -1 / rho - 2,               (AC)

rho in [-1/2, 0]: -1/2 when nothing repeats, 0 when nothing but a drift changes (Box and
Jenkins: the ARIMA(0,1,1) form of exponential smoothing, K = 1 - theta with
rho = -theta / (1 + theta^2)). Per joint, the products are sums over the trial's samples,
weighted over trials by lambda = 1 - 1 / ``averaging.memory``, and rho is estimated as their
correlation coefficient, sum dT_k dT_k-1 / sqrt(sum dT_k^2 sum dT_k-1^2) (the same for
stationary changes, within [-1, 1] while the law still converges and the changes shrink); until
``memory`` trials' changes are in, and wherever rho >= 0, K = 1. K never goes below
``averaging.min_gain``.

The law's deadbeat-like step carries a trial's non-repeating error whole into the next
feed-forward (at the `voluntary` floor rho is -0.27 to -0.43 per joint over trials 500-1000:
docs/patient-aware.md); (KG) averages it down while a repeating change still raises rho and
with it K. A repeating part that is not a random walk (a patient who learns from the same
errors) is why ``min_gain`` exists.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..params.config import Config


def local_level_gain(rho: np.ndarray) -> np.ndarray:
    """(KG) with (AC): the steady-state Kalman gain of the local-level model (LL) from the
    lag-1 autocorrelation ``rho`` of its changes, per joint; 1 for rho >= 0 (nothing to
    average), 0 for rho <= -1/2 (nothing repeats)."""
    rho = np.asarray(rho, dtype=float)
    inside = (rho < 0.0) & (rho > -0.5)
    safe = np.where(inside, rho, -0.25)
    s = -1.0 / safe - 2.0
    gain = 0.5 * (-s + np.sqrt(s * s + 4.0 * s))
    return np.where(rho >= 0.0, 1.0, np.where(inside, gain, 0.0))


@dataclass(eq=False)
class AveragingGain:
    """(KG) per joint from (AC): the weighted sums of the target's changes and their lag-1
    products over the trials so far."""

    memory: float
    min_gain: float
    joints: int
    _previous: np.ndarray | None = field(default=None, init=False, repr=False)
    """The last target, in the next trial's coordinates."""
    _change: np.ndarray | None = field(default=None, init=False, repr=False)
    """The last change of the target."""
    _power: np.ndarray = field(init=False, repr=False)
    _power_before: np.ndarray = field(init=False, repr=False)
    _lagged: np.ndarray = field(init=False, repr=False)
    _pairs: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        self._power = np.zeros(self.joints)
        self._power_before = np.zeros(self.joints)
        self._lagged = np.zeros(self.joints)

    @property
    def forgetting(self) -> float:
        """lambda = 1 - 1 / memory: the weight of a trial's products one trial later."""
        return 1.0 - 1.0 / self.memory

    @property
    def rho(self) -> np.ndarray:
        """(AC) per joint from the weighted sums, as a correlation coefficient (NaN before the
        first pair of changes, or where nothing changed)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(self._lagged / np.sqrt(self._power * self._power_before)) \
                if self._pairs else np.full(self.joints, np.nan)

    def gain(self) -> np.ndarray:
        """K per joint for the next update: 1 until ``memory`` pairs of changes are in, then
        (KG) from (AC), at least ``min_gain``."""
        if self._pairs < math.ceil(self.memory):
            return np.ones(self.joints)
        rho = np.nan_to_num(self.rho, nan=0.0)  # no change at all: nothing to average
        return np.maximum(local_level_gain(rho), self.min_gain)

    def observe(self, target: np.ndarray, shift: np.ndarray | None = None) -> np.ndarray:
        """Count the target T_k (samples, joints) of a learned-from trial and return K for its
        update. ``shift`` is what the next feed-forward gives up outside the law (the identified
        forces' hand-over): the target's next change is taken in the next trial's coordinates,
        so it is not counted as a change of what the arm needs."""
        target = np.asarray(target, dtype=float)
        if self._previous is not None:
            change = target - self._previous
            if self._change is not None:
                lam = self.forgetting
                self._power = lam * self._power + np.sum(change * change, axis=0)
                self._power_before = lam * self._power_before + np.sum(
                    self._change * self._change, axis=0)
                self._lagged = lam * self._lagged + np.sum(change * self._change, axis=0)
                self._pairs += 1
            self._change = change
        self._previous = target if shift is None else target - np.asarray(shift, dtype=float)
        return self.gain()


def averaging_of(config: Config) -> AveragingGain | None:
    """The config's (KG) (``averaging.*``), or None when ``averaging.memory`` is 0 (off)."""
    memory = float(config["averaging.memory"])
    if memory <= 0.0:
        return None
    return AveragingGain(memory, float(config["averaging.min_gain"]), config.joints)
