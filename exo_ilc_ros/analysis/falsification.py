"""Falsification (issue 33): a search over the population's ranges for the patient that makes a
law fail worst, the idea of S-TaLiRo and Breach (optimise over a model's parameters for a run
that violates a requirement) with Optuna's CMA-ES sampler over the unit cube of
:mod:`exo_ilc_ros.core.population.distributions` (so only patients the ranges allow).

Objective (maximised, :func:`failure_score`) of a patient run for N trials: log10 of the worst
joint's true max |e| at the last trial; a run with an aborted trial scores above every finite
error (:data:`ABORT_SCORE` plus the share of trials aborted); a run that is not finite scores
highest (:data:`NONFINITE_SCORE`). The search starts from the population's worst patient
(CMA-ES's mean) and asks a batch of candidates at a time, run like the population's cells
(process pool or Dask)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import optuna

from ..core.params.config import Config
from ..core.population.certificate import (
    PatientOutcome,
    feedforward_limit,
    patient_cell,
    patient_config,
    patient_outcome,
)
from ..core.population.distributions import (
    Patient,
    PopulationSpec,
    cube_coordinates,
    patient_from_unit,
)
from ..core.programs.study import CellResult, StudyCell
from .study import run_cells

ABORT_SCORE = 10.0
"""Score of a run with an aborted trial (log10 of an error: 10 is 1e10 rad, above any)."""
NONFINITE_SCORE = 20.0
"""Score of a run that is not finite (or failed)."""
SIGMA0 = 0.25
"""CMA-ES's initial step on the unit cube."""


def failure_score(outcome: PatientOutcome) -> float:
    """How badly the law fails the patient (higher: worse)."""
    if not outcome.finite:
        return NONFINITE_SCORE
    if outcome.aborts:
        return ABORT_SCORE + outcome.aborts / max(outcome.trials, 1)
    return math.log10(max(outcome.final_error, 1e-300))


@dataclass(frozen=True)
class Found:
    """A patient the search ran, with its outcome and score."""

    patient: Patient
    outcome: PatientOutcome
    score: float


class Search(NamedTuple):
    """What the falsification search is given: how many patients it may run, its sampler's
    seed (also every patient's ``patient.seed``), and the point of the unit cube CMA-ES starts
    from (read with every MAS grade an equal share, :func:`..core.population.distributions.
    search_point`; None: the cube's centre)."""

    budget: int
    seed: int
    start: Mapping[str, float] | None = None


class Pool(NamedTuple):
    """Where the searched patients run: the local process pool's workers or a Dask cluster
    (an address or a client), as :func:`.study.run_cells` takes them."""

    workers: int = 1
    dask: str | Any | None = None


LOCAL = Pool()
"""One local worker."""


def falsify(base: Config, spec: PopulationSpec, label: str, trials: int, search: Search,
            pool: Pool = LOCAL, on_found: Callable[[Found], None] | None = None) -> list[Found]:
    """Every patient the search ran (``search.budget`` of them) on ``base`` (the law laid
    over its arm, :func:`..core.population.certificate.patient_config`), worst first."""
    budget, seed, start = search
    workers, dask = pool
    names = cube_coordinates(base, spec)
    x0 = {n: float(np.clip((start or {}).get(n, 0.5), 0.0, 1.0)) for n in names}
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    with warnings.catch_warnings():  # x0 and sigma0: deprecated in optuna 4.9, removed in 6
        warnings.simplefilter("ignore", FutureWarning)
        sampler = optuna.samplers.CmaEsSampler(x0=x0, sigma0=SIGMA0, seed=seed,
                                               warn_independent_sampling=False)
    study = optuna.create_study(direction="maximize", sampler=sampler)
    batch = max(1, workers)
    found: list[Found] = []
    while len(found) < budget:
        asked = [study.ask() for _ in range(min(batch, budget - len(found)))]
        patients = []
        cells: list[StudyCell] = []
        for trial in asked:
            point = {n: trial.suggest_float(n, 0.0, 1.0) for n in names}
            patient = patient_from_unit(base, spec, point, index=len(found) + len(cells),
                                        uniform_grades=True)
            patient.overrides["patient.seed"] = int(seed)
            config = patient_config(base, patient, trials)
            patients.append(patient)
            cells.append(patient_cell(label, config, patient))
        results: list[CellResult] = run_cells(cells, workers, dask)
        for trial, patient, cell, result in zip(asked, patients, cells, results, strict=True):
            outcome = patient_outcome(cell.seed, result, trials, feedforward_limit(cell.values))
            score = failure_score(outcome)
            study.tell(trial, score)
            item = Found(patient, outcome, score)
            found.append(item)
            if on_found is not None:
                on_found(item)
    return sorted(found, key=lambda f: f.score, reverse=True)


def falsification_json(found: Sequence[Found], budget: int, trials: int,
                       written: Sequence[str], worst: int) -> dict[str, Any]:
    """The search for the certificate's JSON: budget, the worst patients found."""
    return {"budget": budget, "trials": trials, "sampler": "optuna CmaEsSampler",
            "worst": [{"score": f.score, **f.outcome.to_json(),
                       "unit": f.patient.unit, "overrides": f.patient.overrides}
                      for f in found[:worst]],
            "scenarios": list(written)}
