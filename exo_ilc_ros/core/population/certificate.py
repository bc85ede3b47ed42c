"""A law's certificate over a population of patients (issue 33): every patient run as one cell
of the study (:func:`..programs.study.run_cell`), each reduced to a :class:`PatientOutcome`, the
population to a :class:`Certificate` with a pass or fail against the issue's criteria
(:data:`CRITERIA`).

Definitions (docs/every-patient.md), with K the trials run and the bound the config's
``error_bound``, on the worst joint's *true* max |e| per trial:

- **finite**: the run reached trial K with every error, learned input and effort finite.
- **bounded**: finite, the growth check (``core.convergence.growth``, as the study) does not
  flag the learned input, and no joint's learned input ends held at ``feedforward_limit``
  (*at its limit*: the limit, not the learning, holds it).
- **within the bound by trial n**: within it at trial n and every later trial (the study's
  *settled* trial <= n); *first* is the first trial within it.
- **aborts**: trials the error envelope aborted; *in a row*: the longest run of consecutive ones.
- **final error**: the worst joint's true max |e| at the last trial run (inf: not finite).
- **peak cuff force** (a person with muscles strapped in, issue 34): per cuff (upper arm,
  forearm), the highest |force| it pressed into the person over every trial (N), and the
  highest |torque| (N m); the population's max and 95th percentile of the patients' worst cuff.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..convergence.growth import held_at_limit
from ..errors import ConfigError
from ..params.config import Config
from ..programs.study import CellResult, StudyCell
from ..programs.study_rows import seed_outcome
from .distributions import Patient

CRITERIA = {"within_by_10_share": 0.95, "within_by_25_share": 1.0, "abort_run_limit": 3,
            "abort_total_limit": 2}
"""The issue's pass: every patient finite and bounded, none with 3 aborted trials in a row or
more than 2 in all, within the bound by trial 10 in >= 95 % and by trial 25 in all."""


def longest_run(trials: Sequence[int]) -> int:
    """The longest run of consecutive trial numbers (``[2, 3, 4, 7]`` -> 3)."""
    best = run = 0
    previous: int | None = None
    for k in sorted(set(trials)):
        run = run + 1 if previous is not None and k == previous + 1 else 1
        best = max(best, run)
        previous = k
    return best


@dataclass(frozen=True)
class PatientOutcome:
    """One patient's run reduced to the certificate's numbers."""

    index: int
    trials: int
    finite: bool
    growing: bool
    first: int | None
    settled: int | None
    aborts: int
    abort_run: int
    final_error: float
    """Worst joint's true max |e| at the last trial (rad; inf if not finite)."""
    worst_error_per_trial: tuple[float, ...]
    """Worst joint's true max |e| per trial (rad; NaN where not finite)."""
    failure: str | None
    at_limit: bool = False
    """Some joint's learned input ends held at ``feedforward_limit``
    (:func:`..convergence.growth.held_at_limit`)."""
    peak_cuff_force: tuple[float, ...] | None = None
    """Per cuff (upper arm, forearm), the peak |force| over every trial (N); None: no person
    strapped in."""
    peak_cuff_torque: tuple[float, ...] | None = None
    """Per cuff, the peak |torque| over every trial (N m); None: no person."""

    @property
    def worst_cuff_force(self) -> float | None:
        """The patient's highest cuff force, either cuff (N; None: no person)."""
        return None if not self.peak_cuff_force else max(self.peak_cuff_force)

    @property
    def bounded(self) -> bool:
        """Finite, not growing and not held at its limit."""
        return self.finite and not self.growing and not self.at_limit

    def within_by(self, trial: int) -> bool:
        """Within the bound from trial ``trial`` (or earlier) to the last."""
        return self.settled is not None and self.settled <= trial

    @property
    def passes(self) -> bool:
        """Meets every per-patient criterion (bounded, aborts, within by trial 25)."""
        return self.bounded and self.abort_run < CRITERIA["abort_run_limit"] and \
            self.aborts <= CRITERIA["abort_total_limit"] and self.within_by(25)

    def severity(self) -> tuple[float, ...]:
        """Sorts the worst patients first: not finite, then most aborts in a row, most aborts,
        never within the bound, the latest settled trial, the largest final error."""
        return (0.0 if self.finite else 1.0, float(self.abort_run), float(self.aborts),
                1.0 if self.settled is None else 0.0,
                float(self.settled or 0), self.final_error)

    def to_json(self) -> dict[str, Any]:
        """Its entry of the certificate's JSON."""
        def number(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None
        return {"index": self.index, "trials": self.trials, "finite": self.finite,
                "growing": self.growing, "at_limit": self.at_limit,
                "bounded": self.bounded, "first": self.first,
                "settled": self.settled, "aborts": self.aborts, "abort_run": self.abort_run,
                "final_error": number(self.final_error), "failure": self.failure,
                "passes": self.passes,
                "worst_error_per_trial": [number(x) for x in self.worst_error_per_trial],
                **({} if self.peak_cuff_force is None else {
                    "peak_cuff_force_N": [number(x) for x in self.peak_cuff_force],
                    "peak_cuff_torque_Nm": [number(x) for x in self.peak_cuff_torque or ()]})}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PatientOutcome:
        """Read back :meth:`to_json`."""
        def number(x: float | None) -> float:
            return math.nan if x is None else float(x)
        def cuffs(key: str) -> tuple[float, ...] | None:
            return None if key not in data else tuple(number(x) for x in data[key])
        final = data["final_error"]
        return cls(int(data["index"]), int(data["trials"]), bool(data["finite"]),
                   bool(data["growing"]), data["first"], data["settled"], int(data["aborts"]),
                   int(data["abort_run"]), math.inf if final is None else float(final),
                   tuple(number(x) for x in data["worst_error_per_trial"]), data["failure"],
                   bool(data.get("at_limit", False)), cuffs("peak_cuff_force_N"),
                   cuffs("peak_cuff_torque_Nm"))


def patient_outcome(index: int, result: CellResult, trials: int,
                    limit: np.ndarray | None = None) -> PatientOutcome:
    """A patient's cell reduced (:func:`..programs.study_rows.seed_outcome` for first, settled,
    finite and growth); ``limit``: the run's ``feedforward_limit`` per joint (0 or None: no
    limit; :func:`feedforward_limit`)."""
    seed = seed_outcome(result, trials)
    worst = np.max(result.true_max_abs_error, axis=1) if result.trials else np.zeros(0)
    final = float(worst[-1]) if seed.finite and worst.size else math.inf
    at_limit = bool(np.any(held_at_limit(result.max_abs_feedforward, limit)))

    def peak(per_trial: np.ndarray | None) -> tuple[float, ...] | None:
        if per_trial is None or not per_trial.size:
            return None
        return tuple(float(x) for x in np.max(per_trial, axis=0))
    return PatientOutcome(index, result.trials, seed.finite, bool(np.any(seed.growing)),
                          seed.first, seed.settled, len(result.aborted),
                          longest_run(result.aborted), final,
                          tuple(float(x) for x in worst),
                          result.failure or result.nonfinite, at_limit,
                          peak(result.peak_cuff_force), peak(result.peak_cuff_torque))


def feedforward_limit(values: Mapping[str, Any]) -> np.ndarray | None:
    """A run's ``feedforward_limit`` per joint from its values (a 0 entry: no limit, inf)."""
    limit = np.asarray(values["feedforward_limit"], dtype=float)
    return np.where(limit > 0.0, limit, np.inf) if np.any(limit > 0.0) else None


def _percentile(values: Sequence[int | None], q: float) -> float | None:
    """The q-th percentile of trial numbers, a patient never within counting as infinitely
    late (None: the percentile falls among those)."""
    data = np.array([math.inf if v is None else float(v) for v in values])
    if not data.size:
        return None
    value = float(np.percentile(data, q, method="higher"))
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class Certificate:
    """A law's certificate on one arm over a population."""

    label: str
    patients: int
    trials: int
    error_bound: float
    outcomes: tuple[PatientOutcome, ...]

    def share(self, test: str) -> float:
        """Share of patients for which ``test`` holds (an attribute or ``within_by_N``)."""
        if not self.outcomes:
            return math.nan
        if test.startswith("within_by_"):
            n = int(test.rsplit("_", 1)[1])
            hits = [o.within_by(n) for o in self.outcomes]
        elif test == "any_abort":
            hits = [o.aborts > 0 for o in self.outcomes]
        elif test == "abort_run_3":
            hits = [o.abort_run >= CRITERIA["abort_run_limit"] for o in self.outcomes]
        elif test == "aborts_over_2":
            hits = [o.aborts > CRITERIA["abort_total_limit"] for o in self.outcomes]
        else:
            hits = [bool(getattr(o, test)) for o in self.outcomes]
        return sum(hits) / len(hits)

    def settled_percentile(self, q: float) -> float | None:
        """Trials to the bound (settled), q-th percentile over patients (None: never)."""
        return _percentile([o.settled for o in self.outcomes], q)

    def first_percentile(self, q: float) -> float | None:
        """First trial within the bound, q-th percentile over patients (None: never)."""
        return _percentile([o.first for o in self.outcomes], q)

    def cuff_force_percentile(self, q: float) -> float | None:
        """The q-th percentile over patients of each one's highest cuff force (N; None: no
        patient with a person strapped in)."""
        forces = [o.worst_cuff_force for o in self.outcomes if o.worst_cuff_force is not None]
        return float(np.percentile(forces, q)) if forces else None

    def cuff_peaks(self) -> dict[str, list[float]] | None:
        """Per cuff, the max over patients of the peak force (N) and torque (N m); None: no
        person."""
        forces = [o.peak_cuff_force for o in self.outcomes if o.peak_cuff_force]
        torques = [o.peak_cuff_torque for o in self.outcomes if o.peak_cuff_torque]
        if not forces:
            return None
        return {"force_N": [float(x) for x in np.max(forces, axis=0)],
                "torque_Nm": [float(x) for x in np.max(torques, axis=0)] if torques else []}

    def reasons(self) -> list[str]:
        """Why it fails the issue's criteria (empty: it passes)."""
        out = []
        n = len(self.outcomes)
        if n < self.patients:
            out.append(f"only {n} of {self.patients} patients ran")
        if self.trials < 25:
            out.append(f"{self.trials} trials: the criteria need 25")
        if self.share("bounded") < 1.0:
            out.append(f"{n - round(self.share('bounded') * n)} patient(s) not finite and "
                       "bounded")
        if self.share("abort_run_3"):
            out.append(f"{round(self.share('abort_run_3') * n)} patient(s) with "
                       f"{CRITERIA['abort_run_limit']} aborted trials in a row")
        if self.share("aborts_over_2"):
            out.append(f"{round(self.share('aborts_over_2') * n)} patient(s) with more than "
                       f"{CRITERIA['abort_total_limit']} aborted trials")
        if self.share("within_by_10") < CRITERIA["within_by_10_share"]:
            out.append(f"within the bound by trial 10 in {100 * self.share('within_by_10'):.1f}"
                       f" % (< {100 * CRITERIA['within_by_10_share']:g} %)")
        if self.share("within_by_25") < CRITERIA["within_by_25_share"]:
            out.append(f"within the bound by trial 25 in {100 * self.share('within_by_25'):.1f}"
                       " % (not all)")
        return out

    @property
    def passes(self) -> bool:
        """The issue's criteria (:data:`CRITERIA`) all hold."""
        return not self.reasons()

    def worst(self, count: int) -> list[PatientOutcome]:
        """The ``count`` worst patients (:meth:`PatientOutcome.severity`)."""
        return sorted(self.outcomes, key=lambda o: o.severity(), reverse=True)[:count]

    def summary(self) -> dict[str, Any]:
        """The certificate's numbers (JSON's ``summary``)."""
        return {"patients": len(self.outcomes), "trials": self.trials,
                "error_bound": self.error_bound,
                **{f"share_{k}": self.share(k) for k in (
                    "finite", "bounded", "within_by_10", "within_by_25", "any_abort",
                    "abort_run_3", "aborts_over_2", "passes")},
                "settled_median": self.settled_percentile(50),
                "settled_p95": self.settled_percentile(95),
                "first_median": self.first_percentile(50),
                "first_p95": self.first_percentile(95),
                **({} if self.cuff_peaks() is None else {
                    "cuff_force_max_N": self.cuff_force_percentile(100),
                    "cuff_force_p95_N": self.cuff_force_percentile(95),
                    "cuff_peaks_per_cuff": self.cuff_peaks()}),
                "passes": self.passes, "reasons": self.reasons()}


def certificate(label: str, patients: int, trials: int, error_bound: float,
                outcomes: Sequence[PatientOutcome]) -> Certificate:
    """The certificate of the outcomes (sorted by patient index)."""
    return Certificate(label, patients, trials, error_bound,
                       tuple(sorted(outcomes, key=lambda o: o.index)))


def patient_config(base: Config, patient: Patient, trials: int,
                   extra: Mapping[str, Any] | None = None) -> Config:
    """The configuration of one patient's run: ``base`` (the config file and its overlays,
    loaded once: ``load_config(path, overrides, overlays)`` is ``load_config(path,
    overlays=overlays).replace(overrides)``), then the patient's overrides, the trial count
    (every trial runs) and ``extra``."""
    overrides: dict[str, Any] = {**patient.overrides, "max_trials": int(trials),
                                 "stop_when_settled": 0, **(extra or {})}
    try:
        return base.replace(overrides)
    except ConfigError as exc:
        raise ConfigError(exc.key, f"{exc.rule} (patient {patient.index}: "
                          f"{patient.describe()})", exc.source) from None


def patient_cell(label: str, config: Config, patient: Patient) -> StudyCell:
    """The study cell that runs one patient (``seed`` is its index)."""
    return StudyCell(label, f"patient {patient.index}", float(config["mass_uncertainty"]),
                     int(patient.index), config.values)
