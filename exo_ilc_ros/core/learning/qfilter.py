"""The Q-filter of robust ILC: a zero-phase low-pass applied to the learned feed-forward after
every update, and the wrapper that adds it (and an optional bound) to any learning law.

With the filtered update u_{k+1} = Q (u_k + L e_k), the trial-to-trial factor at frequency w is
|Q(e^jw)| |1 - L(e^jw) P(e^jw)| (:mod:`.convergence`): Q <= 1 everywhere and ~0 above the cut-off,
so the band where the unfiltered factor exceeds 1 can be switched off. The price is that the
learned input cannot represent content above the cut-off, so the error floor rises there.

Edge handling: a trial is a finite record (N+1 samples) and a forward-backward filter must
decide what lies beyond both ends. The choice here is even (mirror) padding,
``sosfiltfilt(..., padtype="even")`` with scipy's default pad length (shorter for records
shorter than it), on the second-order-sections form of the Butterworth filter. A constant
passes exactly (DC gain 1 up to the ends) and the filter as an (N+1) x (N+1) matrix has 2-norm
1.006 at 5 Hz, so it hardly amplifies a learned input. What decides is the lifted
trial-to-trial map Q S of the paper's loop (joint 1, Q at 5 Hz): its spectral radius is 0.848
with even padding (as with constant padding or Gustafsson's method),
but 0.988 with scipy's default odd padding, which keeps the end value *and the end slope*: the
feed-forward of the last sample is never applied, so it integrates the final error trial after
trial and the odd extension hands that ramp on (1.000 with a pad of three filter time constants).
Gustafsson's method (``filtfilt(..., method="gust")``) does as well as even padding but exists
only for the transfer-function (b, a) form, which is numerically unstable for higher orders at low
cut-offs (order 4 at 0.05 Hz at 100 Hz); the SOS form is not. See ``test_qfilter``.
"""

from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from ..loop.record import TrialRecord
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .laws import FeedforwardUpdate, LearningLaw


def scipy_signal() -> ModuleType:
    """``scipy.signal``, imported where a filter is first made or run: importing it takes
    0.3-1 s (scipy.stats with it), which a run without a Q-filter or identification, and every
    command's start-up, would pay for nothing."""
    return importlib.import_module("scipy.signal")


def butter_sos(order: int, normalised_cutoff: float) -> np.ndarray:
    """``butter(order, normalised_cutoff, output="sos")`` (a copy of the design made once per
    process: a session makes a Q-filter every trial)."""
    return _butter_sos(order, normalised_cutoff).copy()


@functools.lru_cache(maxsize=64)
def _butter_sos(order: int, normalised_cutoff: float) -> np.ndarray:
    return np.asarray(scipy_signal().butter(order, normalised_cutoff, output="sos"))


@dataclass(frozen=True, eq=False)
class QFilter:
    """Zero-phase Butterworth low-pass: ``butter(order, cutoff_hz)`` run forwards and backwards.

    The forward-backward filter has the frequency response Q(e^jw) = |H(e^jw)|^2 (real,
    non-negative: zero phase), so |Q| = 1/2 at ``cutoff_hz`` and the roll-off is 2 * order
    times 20 dB per decade.
    """

    cutoff_hz: float
    order: int
    period: float
    sos: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        nyquist = 0.5 / self.period
        if not 0.0 < self.cutoff_hz < nyquist:
            raise ValueError(f"Q-filter cut-off must be in (0, {nyquist:g}) Hz (the Nyquist "
                             f"frequency of the {self.period:g} s control period), got "
                             f"{self.cutoff_hz:g}")
        if self.order < 1:
            raise ValueError(f"Q-filter order must be >= 1, got {self.order}")
        object.__setattr__(self, "sos", butter_sos(self.order, self.cutoff_hz / nyquist))

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Q x along axis 0 (time), per column (joint): zero-phase ``filtfilt``."""
        x = np.asarray(x, dtype=float)
        if x.shape[0] < 2:
            return x.copy()
        padlen = min(3 * (2 * len(self.sos) + 1), x.shape[0] - 1)  # scipy's default, or less
        return np.asarray(scipy_signal().sosfiltfilt(self.sos, x, axis=0, padtype="even",
                                             padlen=padlen))

    def response(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Q(e^jw) = |H(e^jw)|^2 at ``frequency_hz`` (real, in [0, 1])."""
        w = 2.0 * np.pi * np.asarray(frequency_hz, dtype=float) * self.period
        _, h = scipy_signal().sosfreqz(self.sos, worN=w)
        return np.asarray(np.abs(h) ** 2)


@dataclass(frozen=True, eq=False)
class QFilteredLaw:
    """Any :class:`LearningLaw` with its learned input filtered and (optionally) bounded:

    u_ff,k+1 = sat_U(Q(inner update)),

    sat_U clipping each joint to +-``feedforward_limit`` (None: no bound). The first trial's
    feed-forward passes through unchanged.
    """

    inner: LearningLaw
    qfilter: QFilter | None
    feedforward_limit: np.ndarray | None = None

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        """The inner law's first feed-forward."""
        return self.inner.initial_feedforward(reference)

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        """The inner update, then the Q-filter, then the bound."""
        step = self.inner.update(record)
        feedforward = step.feedforward
        if self.qfilter is not None:
            feedforward = self.qfilter.apply(feedforward)
        if self.feedforward_limit is not None:
            feedforward = np.clip(feedforward, -self.feedforward_limit, self.feedforward_limit)
        return FeedforwardUpdate(feedforward, step.levels, step.notes)


def qfilter_of(config: Config) -> QFilter | None:
    """The config's Q-filter (``q_filter.*``), or None if disabled."""
    if not config["q_filter.enabled"]:
        return None
    return QFilter(config["q_filter.cutoff_hz"], config["q_filter.order"],
                   config["control.period"])


def feedforward_limit_of(config: Config) -> np.ndarray | None:
    """The config's ``feedforward_limit`` per joint (0 entries: unbounded), or None if all 0."""
    limit = np.asarray(config["feedforward_limit"], dtype=float)
    if not np.any(limit > 0.0):
        return None
    return np.where(limit > 0.0, limit, np.inf)
