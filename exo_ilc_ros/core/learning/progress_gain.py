"""A position learning gain that backs off once the error stops falling (not in the paper;
issue 28's "a learning gain that backs off when the error reaches the non-repeating floor").

Per joint j, after trial k with max_t |e_j| = m_k,j (measured) and the lowest m of the earlier
completed trials m*_j,

    active_j = m_k,j < (1 - margin) m*_j     (trial 1: active),                       (PG)
    u_ff,k+1 += Q[G_j active_j e_k,j],

G = ``progress_gain.position`` (the units of u per rad), Q the law's Q-filter. While the error
keeps falling, the joint learns its low frequencies harder (the shipped law's own position gain
is K_P, from the PD part of its memory); once it stops making new lows (the floor: the
patient's and the sensors' variation, or a noise-free loop's fixed point) the law is the plain
one again, so the extra gain does not follow non-repeating variation. Meant for a tail the law
trails by one trial, e.g. a patient whose own learned torque decays from trial to trial
(``learning`` scenario: docs/patient-aware.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params.config import Config
from .qfilter import QFilter, qfilter_of


@dataclass(frozen=True, eq=False)
class ProgressGain:
    """(PG): the extra position gain per joint and the share a new low must beat."""

    gain: np.ndarray
    margin: float
    qfilter: QFilter | None = None

    def active(self, max_abs_error: np.ndarray, lowest: np.ndarray | None) -> np.ndarray:
        """Per joint: the error ``max_abs_error`` is a new low by more than ``margin`` against
        ``lowest`` (None: no earlier trial, every joint active)."""
        m = np.asarray(max_abs_error, dtype=float)
        if lowest is None:
            return np.ones(m.shape, dtype=bool)
        return np.asarray(m < (1.0 - self.margin) * np.asarray(lowest, dtype=float))

    def step(self, error: np.ndarray, active: np.ndarray) -> np.ndarray | None:
        """Q[G active e] (samples, joints); None when no joint with a gain is active."""
        gain = np.where(active, self.gain, 0.0)
        if not np.any(gain > 0.0):
            return None
        added = gain * np.asarray(error, dtype=float)
        return added if self.qfilter is None else self.qfilter.apply(added)


def progress_gain_of(config: Config) -> ProgressGain | None:
    """The config's (PG) (``progress_gain.*``), or None when every gain is 0."""
    gain = np.asarray(config["progress_gain.position"], dtype=float)
    if not np.any(gain > 0.0):
        return None
    return ProgressGain(gain, float(config["progress_gain.margin"]), qfilter_of(config))
