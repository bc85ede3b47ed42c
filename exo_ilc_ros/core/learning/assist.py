"""Assist-as-needed learning (Emken, Bobrow and Reinkensmeyer, J NeuroEng Rehabil 4:8, 2007):
a forgetting factor and an error deadband around any learning law.

Emken's law is u_{k+1} = f u_k + g e_k with f < 1: the learned assistance decays toward zero
unless the error calls for it, and errors within the person's own trial-to-trial variability
(+-3 sigma) are not learned, with a tanh transition of width sigma/2. Here, around a law whose
update is u_{k+1} = m_k + Delta_k (m_k its memory: the previous feed-forward or whole input,
Delta_k what it learned from trial k's errors):

    u_{k+1}(t) = f m_k(t) + G(e_k(t)) Delta_k(t),                                    (AAN)
    G(e) = 1/2 (1 + tanh((|e| - d) / w)),   d = n_d sigma,  w = n_w sigma,         (AAN-G)

per sample t and joint, sigma the joint's variability (rad), n_d = ``deadband_sigmas`` (3),
n_w = ``transition_sigmas`` (1/2). G is ~0 inside the deadband (G(0) = 6.1e-6 for 3 and 1/2),
1/2 at its edge |e| = d and ~1 beyond; sigma = 0 means no deadband (G = 1). The gate multiplies
each sample's update, so for the pointwise laws (sign, linear) it is exactly learning from the
deadbanded error; f = 1 and sigma = 0 give the inner law back unchanged.

Trial to trial (``analyze-loop``), with the inner law's factor F = m - L P per frequency
(:mod:`.convergence`), (AAN) has F_aan = f m + G (F - m): affine in the gate, so its modulus over
G in [0, 1] is largest at an end: |f m| inside the deadband (forgetting only) or
|F - (1 - f) m| outside it (learning). :func:`aan_factor` is that worst case.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..loop.record import TrialRecord
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .laws import FeedforwardUpdate, LearningLaw, Memory, _memory


def deadband_gate(error: np.ndarray, deadband: np.ndarray, width: np.ndarray) -> np.ndarray:
    """G(e) of (AAN-G) per sample and joint: 1/2 (1 + tanh((|e| - d) / w)); 1 where w = 0."""
    e = np.abs(np.asarray(error, dtype=float))
    d = np.broadcast_to(np.asarray(deadband, dtype=float), e.shape)
    w = np.broadcast_to(np.asarray(width, dtype=float), e.shape)
    safe = np.where(w > 0.0, w, 1.0)
    return np.asarray(np.where(w > 0.0, 0.5 * (1.0 + np.tanh((e - d) / safe)), 1.0))


def memory_of(law: LearningLaw, record: TrialRecord) -> np.ndarray:
    """m_k of (AAN): what ``law`` carries over from trial k (its ``memory`` option; the
    previous feed-forward for a law without one, e.g. norm-optimal)."""
    memory = getattr(law, "memory", Memory.FEEDFORWARD)
    return _memory(record, memory if isinstance(memory, Memory) else Memory.FEEDFORWARD)


@dataclass(frozen=True, eq=False)
class AssistAsNeededLaw:
    """(AAN) around ``inner``: forgetting factor ``forgetting`` (f, in (0, 1]), deadband
    ``deadband`` and transition width ``width`` per joint (rad). Wrap it in a
    :class:`~.qfilter.QFilteredLaw` to filter its result (``build_law`` does)."""

    inner: LearningLaw
    forgetting: float
    deadband: np.ndarray
    width: np.ndarray

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        """The inner law's first feed-forward."""
        return self.inner.initial_feedforward(reference)

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        """(AAN): f m_k + G(e_k) (inner update - m_k)."""
        step = self.inner.update(record)
        memory = memory_of(self.inner, record)
        gate = deadband_gate(record.error, self.deadband, self.width)
        feedforward = self.forgetting * memory + gate * (step.feedforward - memory)
        return FeedforwardUpdate(feedforward, step.levels, step.notes)


@dataclass(frozen=True)
class AssistSettings:
    """The config's ``assist_as_needed.*``: f, and d, w per joint (rad)."""

    forgetting: float
    deadband: np.ndarray
    width: np.ndarray


def assist_of(config: Config) -> AssistSettings | None:
    """The config's assist-as-needed settings, or None when ``assist_as_needed.enabled`` is
    false."""
    if not config["assist_as_needed.enabled"]:
        return None
    sigma = np.asarray(config["assist_as_needed.variability"], dtype=float)
    return AssistSettings(float(config["assist_as_needed.forgetting"]),
                          config["assist_as_needed.deadband_sigmas"] * sigma,
                          config["assist_as_needed.transition_sigmas"] * sigma)


def with_assist(law: LearningLaw, config: Config) -> LearningLaw:
    """``law`` wrapped in :class:`AssistAsNeededLaw` when the config enables it."""
    settings = assist_of(config)
    if settings is None:
        return law
    return AssistAsNeededLaw(law, settings.forgetting, settings.deadband, settings.width)


def aan_factor(inner: np.ndarray, memory: np.ndarray, forgetting: float) -> np.ndarray:
    """Worst |F_aan| over the gate (module docstring): max(|f m|, |F - (1 - f) m|), from the
    inner law's complex factor F and memory m per frequency."""
    inside = np.abs(forgetting * memory)
    outside = np.abs(inner - (1.0 - forgetting) * memory)
    return np.asarray(np.maximum(inside, outside))



def estimate_variability(records: Sequence[TrialRecord]) -> np.ndarray:
    """sigma per joint (rad) for ``assist_as_needed.variability`` from trials of the patient:
    sqrt(mean over t of the variance over trials of e(t)), the measured error the law sees
    (aborted trials left out; at least two trials needed). The trials should be ones where the
    learned input hardly changes (e.g. the last of a settled session), so that what varies is
    the patient, not the learning."""
    errors = np.array([r.error for r in records if not r.aborted])
    if errors.shape[0] < 2:
        raise ValueError("estimating the variability needs at least two completed trials")
    return np.asarray(np.sqrt(np.mean(np.var(errors, axis=0, ddof=1), axis=0)))
