"""The robustness study's table (:mod:`.study` runs the cells): each cell reduced to numbers
(:class:`SeedOutcome`), the cells of one law x scenario x uncertainty reduced over their seeds to
one :class:`StudyRow`."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..convergence.bound import iterations_to_bound
from ..convergence.growth import DEFAULT_WINDOW, MIN_TRIALS, fit_growth
from .study import CellResult

FLOOR_WINDOW = 100
"""Trials whose median is the settled floor (the last ones; all of them if the run is shorter)."""


LATE_ABORT_AFTER = 10
"""An envelope abort after this trial counts against "bounded" (the first trials may still be
learning a large error)."""


@dataclass(frozen=True)
class SeedOutcome:
    """One cell reduced to numbers: what the row takes over seeds."""

    first: int | None
    """First trial with every joint's true max |e| within the bound (None: never)."""
    settled: int | None
    """The trial from which every joint stays within it to the last (None: not at the end)."""
    floor_per_joint: np.ndarray
    """Median of the true max |e| over the last :data:`FLOOR_WINDOW` trials, per joint (NaN
    for a run that did not reach its last trial with finite numbers)."""
    growing: np.ndarray
    """Per joint: the growth check flags its learned input (False where it gives no verdict)."""
    growth_rate: np.ndarray
    """Per joint: fitted growth of log max |u_ff| per trial (NaN: no verdict)."""
    finite: bool
    """Every error, learned input and effort is finite and the run reached its last trial."""
    late_aborts: int
    """Envelope aborts after trial :data:`LATE_ABORT_AFTER`."""

    @property
    def floor(self) -> float:
        """The worst joint's floor (rad)."""
        return float(np.max(self.floor_per_joint)) if self.floor_per_joint.size else np.nan


def growth_window(trials: int) -> int:
    """Trials the growth check fits, as ``exo-ilc simulate`` does: the last 100, at most the
    second half of the run (the first trials' learning is not growth), at least 10."""
    return min(DEFAULT_WINDOW, max(trials // 2, MIN_TRIALS))


def seed_outcome(cell: CellResult, trials: int) -> SeedOutcome:
    """The numbers of one cell: first/settled on the worst joint's true error, the floor over the
    last min(100, K) trials, the growth check (``core.convergence.growth``) on max |u_ff|."""
    errors = cell.true_max_abs_error
    finite = cell.failure is None and cell.nonfinite is None and cell.trials == trials and all(
        bool(np.all(np.isfinite(t))) for t in
        (errors, cell.max_abs_feedforward, cell.max_abs_effort))
    joints = errors.shape[1]
    if cell.trials == 0:
        return SeedOutcome(None, None, np.full(joints, np.nan), np.zeros(joints, bool),
                           np.full(joints, np.nan), False, 0)
    worst = np.max(errors, axis=1, keepdims=True)
    its = iterations_to_bound(worst, cell.error_bound)
    window = errors[-min(FLOOR_WINDOW, cell.trials):]
    floor = np.median(window, axis=0) if finite else np.full(joints, np.nan)  # none: not settled
    with np.errstate(invalid="ignore", divide="ignore"):
        fit = fit_growth(cell.max_abs_feedforward, growth_window(cell.trials))
    growing = np.zeros(joints, bool) if fit is None else np.asarray(fit.growing, bool)
    rate = np.full(joints, np.nan) if fit is None else np.asarray(fit.rate, float)
    late = sum(1 for k in cell.aborted if k > LATE_ABORT_AFTER)
    return SeedOutcome(its.first[0], its.settled[0], floor, growing, rate, finite, late)


@dataclass(frozen=True)
class StudyRow:
    """One law x scenario x mass uncertainty over its seeds: the study table's row."""

    law: str
    scenario: str
    mass_uncertainty: float
    seeds: int
    trials: int
    error_bound: float
    first: int | None
    """The latest over seeds of the first trial with every joint within the bound (None: some
    seed never got there)."""
    settled: int | None
    """The latest over seeds of the trial from which every joint stays within (None: some seed
    is outside at its last trial)."""
    floor: float
    """Median over seeds of the settled floor (worst joint; rad)."""
    floor_low: float
    floor_high: float
    """Smallest and largest settled floor over seeds (rad)."""
    floor_per_joint: tuple[float, ...]
    """Per joint: median over seeds of its floor (rad)."""
    growing_joints: tuple[int, ...]
    """Joints (1-based) whose learned input the growth check flags in some seed."""
    growing_seeds: int
    """Seeds with some joint flagged."""
    max_growth_rate: float
    """Largest fitted growth rate of log max |u_ff| per trial over joints and seeds (NaN: none)."""
    finite: bool
    """Every seed ran to its last trial with finite numbers."""
    failures: tuple[str, ...]
    """Why runs stopped early, per failing seed."""
    peak_effort: float
    """max |effort| over seeds, trials and joints (N m)."""
    at_limit: float
    """Share of samples (over seeds and trials) at which some joint is at its effort limit."""
    aborts: int
    """Envelope aborts, summed over seeds."""
    late_aborts: int
    """Of them, after trial :data:`LATE_ABORT_AFTER`."""
    last_abort: int | None
    """The latest aborted trial over seeds."""

    @property
    def bounded(self) -> bool:
        """Finite, no growth flag, no envelope abort after trial 10: the run can go on."""
        return self.finite and self.growing_seeds == 0 and self.late_aborts == 0

    @property
    def verdict(self) -> str:
        """``bounded``, ``growing``, ``aborts`` or ``failed``."""
        if not self.finite:
            return "failed"
        if self.growing_seeds:
            return "growing"
        if self.late_aborts:
            return "aborts"
        return "bounded"

    def to_json(self) -> dict[str, Any]:
        """The ``rows[]`` entry of the study's JSON."""
        def number(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None

        return {"law": self.law, "scenario": self.scenario,
                "mass_uncertainty": self.mass_uncertainty, "seeds": self.seeds,
                "trials": self.trials, "error_bound": self.error_bound, "first": self.first,
                "settled": self.settled, "floor": number(self.floor),
                "floor_low": number(self.floor_low), "floor_high": number(self.floor_high),
                "floor_per_joint": [number(x) for x in self.floor_per_joint],
                "verdict": self.verdict, "bounded": self.bounded,
                "growing_joints": list(self.growing_joints),
                "growing_seeds": self.growing_seeds,
                "max_growth_rate": number(self.max_growth_rate), "finite": self.finite,
                "failures": list(self.failures), "peak_effort": number(self.peak_effort),
                "at_limit": self.at_limit, "aborts": self.aborts,
                "late_aborts": self.late_aborts, "last_abort": self.last_abort}


def _latest(values: Iterable[int | None]) -> int | None:
    items = list(values)
    return None if any(v is None for v in items) or not items else max(
        v for v in items if v is not None)


def study_row(results: Sequence[CellResult], trials: int) -> StudyRow:
    """The row of the cells of one law x scenario x uncertainty (one per seed)."""
    if not results:
        raise ValueError("a study row needs at least one cell")
    head = results[0]
    outcomes = [seed_outcome(r, trials) for r in results]
    floors = np.array([o.floor for o in outcomes])
    finite_floors = floors[np.isfinite(floors)]
    per_joint = np.array([o.floor_per_joint for o in outcomes])
    growing = np.array([o.growing for o in outcomes])
    rates = np.array([o.growth_rate for o in outcomes])
    efforts = [r.max_abs_effort for r in results if r.max_abs_effort.size]
    peak = max((float(np.max(e)) for e in efforts), default=np.nan)
    samples = sum(r.trials * r.samples for r in results)
    at_limit = sum(int(np.sum(r.samples_at_limit)) for r in results) / samples if samples \
        else 0.0
    aborted = [k for r in results for k in r.aborted]

    def median(x: np.ndarray) -> float:
        return float(np.median(x)) if x.size else np.nan

    return StudyRow(
        head.law, head.scenario, head.mass_uncertainty, len(results), trials, head.error_bound,
        _latest(o.first for o in outcomes), _latest(o.settled for o in outcomes),
        median(finite_floors) if finite_floors.size == floors.size else np.nan,
        float(np.min(floors)) if finite_floors.size == floors.size else np.nan,
        float(np.max(floors)) if finite_floors.size == floors.size else np.nan,
        tuple(median(per_joint[:, j]) for j in range(per_joint.shape[1])),
        tuple(int(j) + 1 for j in np.flatnonzero(np.any(growing, axis=0))),
        int(np.count_nonzero(np.any(growing, axis=1))),
        float(np.nanmax(rates)) if np.any(np.isfinite(rates)) else np.nan,
        all(o.finite for o in outcomes),
        tuple(f"seed {r.seed}: {why}" for r in results for why in (r.failure, r.nonfinite)
              if why),
        peak, float(at_limit), len(aborted), sum(o.late_aborts for o in outcomes),
        max(aborted, default=None))


def study_rows(results: Sequence[CellResult], trials: int) -> list[StudyRow]:
    """One row per law x scenario x uncertainty, in the order their cells first appear."""
    groups: dict[tuple[str, str, float], list[CellResult]] = {}
    for r in results:
        groups.setdefault((r.law, r.scenario, r.mass_uncertainty), []).append(r)
    return [study_row(sorted(group, key=lambda r: r.seed), trials) for group in groups.values()]
