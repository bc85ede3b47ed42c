"""Every trial of one run and what was learned (:class:`RunResult`), whichever runner made it."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np

from ..convergence.bound import IterationsToBound, iterations_to_bound
from ..learning.laws import FeedforwardUpdate
from ..learning.patient_model import JointForceStep
from ..loop.record import TrialRecord


class StopReason(Enum):
    """Why a session is finished."""

    MAX_TRIALS = "max_trials"
    SETTLED = "settled"
    ABORTS = "aborts"
    """Aborted trials in a row (``abort.max_consecutive``), a diverged plant, or an abort
    that left nothing to learn (:mod:`.abort`)."""


@dataclass
class RunResult:
    """Every trial of one run and what was learned."""

    mass_uncertainty: float
    law: str
    error_bound: float
    records: list[TrialRecord] = field(default_factory=list)
    final: FeedforwardUpdate | None = None
    """The feed-forward learned from the last trial (what trial K+1 would use)."""
    patient_memory: tuple[np.ndarray, np.ndarray] | None = None
    """A learning virtual patient's fast and slow states after the run (None: none)."""
    resumed: int = 0
    """Trials restored from the store rather than run (0: none)."""
    stop: StopReason | None = None
    """Why the run ended (max_trials, settled with ``stop_when_settled``, or aborts)."""
    stop_message: str = ""
    """The one message of a run stopped by aborts (joint, time, value, likely cause)."""
    applied: dict[int, dict[str, Any]] = field(default_factory=dict)
    """Live changes per effective trial (the first trial run with them)."""
    notes: dict[int, tuple[str, ...]] = field(default_factory=dict)
    """What the law reported when it learned from a trial (e.g. active constraints), by trial."""
    joint_forces: dict[int, JointForceStep] = field(default_factory=dict)
    """The identification of the patient's joint forces after each trial, by trial
    (``identification.enabled``; empty: off)."""
    person_description: str = ""
    """A person strapped in: the person's display URDF (``core/person/display.py``), which a
    bag of the run carries on ``/person/robot_description`` (""; none)."""

    @property
    def aborted(self) -> list[int]:
        """Trial numbers aborted by the error envelope (learned from over the samples they
        have, :mod:`.abort`)."""
        return [r.trial for r in self.records if r.aborted]

    @property
    def max_abs_errors(self) -> np.ndarray:
        """(K, joints) table of max |e| per trial and joint."""
        return np.array([r.max_abs_error for r in self.records])

    def true_max_abs_errors(self) -> np.ndarray:
        """(K, joints) table of the true max |e| per trial and joint (the plant's state; equal
        to :attr:`max_abs_errors`, the measured one, without sensor effects)."""
        return np.array([r.true_max_abs_error for r in self.records])

    @property
    def max_abs_feedforward(self) -> np.ndarray:
        """(K, joints) table of max |u_ff| per trial and joint."""
        return np.array([np.max(np.abs(r.feedforward), axis=0) for r in self.records])

    @property
    def max_abs_effort(self) -> np.ndarray:
        """(K, joints) table of max |effort| per trial and joint."""
        return np.array([np.max(np.abs(r.effort), axis=0) for r in self.records])

    def iterations_to_bound(self) -> IterationsToBound:
        """First and settled trial per joint with the true max |e| within ``error_bound``."""
        return iterations_to_bound(self.true_max_abs_errors(), self.error_bound)
