"""Iterative learning laws behind one interface: ``update(trial record) -> next feed-forward``.

:class:`SignLaw` is the paper's sgnPDD^2 law, eqs (11)-(13), with :class:`StepSchedule` gains of
eqs (22)-(24); :class:`LinearLaw` the Arimoto-type PDD^2 law it is compared with. Every option the
paper leaves open is an enum here and a parameter in the config.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Protocol

import numpy as np

from ..loop.record import TrialRecord
from ..reference.trajectory import SampledReference


class Memory(Enum):
    """What u_{k-1} of eq (11) is."""

    TOTAL_INPUT = "total_input"
    """The whole input of the previous trial, feed-forward plus PD feedback (open-closed ILC)."""
    FEEDFORWARD = "feedforward"
    """Only the previous trial's feed-forward."""


class ScheduleIndex(Enum):
    """Which error sum selects M' and M''."""

    OWN_SUM = "own_sum"
    """M by |s e|, M' by |s e_dot|, M'' by |s e_ddot| (the paper's text before (13))."""
    POSITION_SUM = "position_sum"
    """All three by |s e|, as eqs (22)-(24) are printed."""


class ErrorSum(Enum):
    """How the sums of eq (13) are formed over the N+1 samples."""

    ABS_OF_SUM = "abs_of_sum"
    """|sum_t e(t)|: signed sum, then its absolute value, as printed."""
    SUM_OF_ABS = "sum_of_abs"
    """sum_t |e(t)|."""


class InitialFeedforward(Enum):
    """The feed-forward of trial 1."""

    ZERO = "zero"
    REFERENCE_ACCELERATION = "reference_acceleration"


def error_sums(record: TrialRecord, mode: ErrorSum) -> np.ndarray:
    """The sums s e, s e_dot, s e_ddot of eq (13) (rows) per joint, as the schedule reads them."""
    signals = (record.error, record.error_velocity, record.error_acceleration)
    if mode is ErrorSum.ABS_OF_SUM:
        return np.array([np.abs(np.sum(x, axis=0)) for x in signals])
    return np.array([np.sum(np.abs(x), axis=0) for x in signals])


def sgn(x: np.ndarray) -> np.ndarray:
    """The sign function of eq (12), with sgn(0) = 0."""
    return np.sign(x)


@dataclass(frozen=True, eq=False)
class StepSchedule:
    """A per-joint step function of an error sum (Fig. 4, eqs (22)-(24)).

    level_high if s > threshold_high; level_mid if threshold_low < s <= threshold_high;
    level_low if s <= threshold_low.
    """

    threshold_low: np.ndarray
    threshold_high: np.ndarray
    level_low: np.ndarray
    level_mid: np.ndarray
    level_high: np.ndarray

    def __post_init__(self) -> None:
        if np.any(self.threshold_low >= self.threshold_high):
            raise ValueError("StepSchedule thresholds must increase (threshold_low < "
                             "threshold_high for every joint)")
        if np.any(np.concatenate([self.level_low, self.level_mid, self.level_high]) < 0.0):
            raise ValueError("StepSchedule levels must be non-negative")

    @classmethod
    def from_values(cls, threshold_low: list[float], threshold_high: list[float],
                    level_low: list[float], level_mid: list[float],
                    level_high: list[float]) -> StepSchedule:
        """From per-joint lists, as in the config."""
        return cls(*(np.asarray(v, dtype=float) for v in
                     (threshold_low, threshold_high, level_low, level_mid, level_high)))

    def band(self, s: np.ndarray) -> np.ndarray:
        """0 (low), 1 (mid) or 2 (high) per joint for the sums ``s``."""
        return np.where(s > self.threshold_high, 2, np.where(s > self.threshold_low, 1, 0))

    def level(self, s: np.ndarray) -> np.ndarray:
        """The step value per joint for the sums ``s``."""
        return np.choose(self.band(s), [self.level_low, self.level_mid, self.level_high])


@dataclass(frozen=True, eq=False)
class FeedforwardUpdate:
    """What a law returns: the next trial's feed-forward and the gains that formed it."""

    feedforward: np.ndarray
    levels: np.ndarray | None = None
    """M, M', M'' (rows) per joint for the sign law; None for laws without levels."""
    notes: tuple[str, ...] = ()
    """What the law reports about this update (e.g. the constraints that were active)."""
    joint_force: np.ndarray | None = None
    """The identified joint forces computed torque adds in the next trial, N m per sample (set
    by the session, :mod:`.patient_model`, never by a law); None: none."""


class LearningLaw(Protocol):
    """An iterative learning law: the first feed-forward, then one update per trial."""

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        """Feed-forward u_ff of trial 1, shape (N+1, joints)."""
        ...

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        """The feed-forward of trial k+1 from the record of trial k."""
        ...


def _initial(reference: SampledReference, initial: InitialFeedforward) -> np.ndarray:
    if initial is InitialFeedforward.REFERENCE_ACCELERATION:
        return reference.acceleration.copy()
    return np.zeros_like(reference.acceleration)


def _memory(record: TrialRecord, memory: Memory) -> np.ndarray:
    return record.control_input if memory is Memory.TOTAL_INPUT else record.feedforward


@dataclass(frozen=True, eq=False)
class SignLaw:
    """The sgnPDD^2 feed-forward of eq (11):

    u_ff,k = u_{k-1} + sgn(e_{k-1}) M_k + sgn(e_dot_{k-1}) M'_k + sgn(e_ddot_{k-1}) M''_k,

    with M, M', M'' chosen per joint by :class:`StepSchedule` from the sums (13) of trial k-1
    (the paper's M_k(s e_k) read causally). The PD part K_P e_k + K_D e_dot_k is added by the
    controller during trial k.
    """

    position: StepSchedule
    velocity: StepSchedule
    acceleration: StepSchedule
    memory: Memory = Memory.TOTAL_INPUT
    schedule_index: ScheduleIndex = ScheduleIndex.OWN_SUM
    error_sum: ErrorSum = ErrorSum.ABS_OF_SUM
    initial: InitialFeedforward = InitialFeedforward.ZERO

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        """Zero, or q_ddot_d, per the ``initial`` option."""
        return _initial(reference, self.initial)

    def levels(self, record: TrialRecord) -> np.ndarray:
        """M, M', M'' (rows) per joint from the sums (13) of ``record``."""
        sums = error_sums(record, self.error_sum)
        own = self.schedule_index is ScheduleIndex.OWN_SUM
        return np.array([self.position.level(sums[0]),
                         self.velocity.level(sums[1] if own else sums[0]),
                         self.acceleration.level(sums[2] if own else sums[0])])

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        """Eq (11): the previous input plus a signed step of each error."""
        m = self.levels(record)
        feedforward = (_memory(record, self.memory) + sgn(record.error) * m[0]
                       + sgn(record.error_velocity) * m[1]
                       + sgn(record.error_acceleration) * m[2])
        return FeedforwardUpdate(feedforward, m)


@dataclass(frozen=True, eq=False)
class LinearLaw:
    """Arimoto-type PDD^2 law: u_ff,k = u_{k-1} + G_p e_{k-1} + G_d e_dot_{k-1} + G_dd e_ddot_{k-1}.

    The update scales with the error instead of stepping by a fixed M; the natural comparison
    for the sign law. Per-joint gains.
    """

    gain_position: np.ndarray
    gain_velocity: np.ndarray
    gain_acceleration: np.ndarray
    memory: Memory = Memory.TOTAL_INPUT
    initial: InitialFeedforward = InitialFeedforward.ZERO

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        """Zero, or q_ddot_d, per the ``initial`` option."""
        return _initial(reference, self.initial)

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        """The previous input plus gains times the errors of the previous trial."""
        feedforward = (_memory(record, self.memory) + self.gain_position * record.error
                       + self.gain_velocity * record.error_velocity
                       + self.gain_acceleration * record.error_acceleration)
        return FeedforwardUpdate(feedforward, None)
