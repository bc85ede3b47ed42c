"""How much one run's iterations to the bound say: the same run again from initial states
perturbed by 1e-12 rad.

The paper's law switches on signs (``sgn`` of the error terms, eq (11)) and its gain levels on
error sums (eq (13)): a last-bit difference can flip a sign at rest, change a level a few trials
later and give another count of iterations to the bound. Each perturbed run starts every trial
from x_d(0) plus a draw of standard deviation :data:`PERTURBATION` rad per joint (the virtual
patient's ``patient.initial.position_sd``, seeded ``patient.seed + i``); the spread of their
counts is what a single count is worth.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..convergence.bound import IterationsToBound
from ..params.config import Config
from ..session.learning_session import run_trials

PERTURBATION = 1e-12
"""Standard deviation (rad) of the perturbed initial position of every trial."""
DEFAULT_PERTURBATIONS = 20
"""Perturbed runs per spread."""


@dataclass(frozen=True)
class IterationSpread:
    """Iterations to the bound of ``count`` perturbed runs: ``first[i][j]`` and
    ``settled[i][j]`` of run i and joint j (None: never / not within at the last trial)."""

    perturbation: float
    first: list[list[int | None]]
    settled: list[list[int | None]]

    @property
    def count(self) -> int:
        """Number of perturbed runs."""
        return len(self.first)

    def cell(self, joint: int) -> str:
        """``first / settled`` of ``joint``, each as ``median [min-max]`` (``never``: not
        within the bound by the last trial)."""
        return (f"{_median_range([r[joint] for r in self.first])} / "
                f"{_median_range([r[joint] for r in self.settled])}")

    def to_json(self) -> dict[str, Any]:
        """``{"perturbation", "count", "first", "settled"}`` (per run and joint)."""
        return {"perturbation": self.perturbation, "count": self.count, "first": self.first,
                "settled": self.settled}


def _median_range(values: Sequence[int | None]) -> str:
    """``median [min-max]`` of trial counts, None ranking above every count (``never``)."""
    ranked = sorted(np.inf if v is None else float(v) for v in values)
    middle = ranked[len(ranked) // 2] if len(ranked) % 2 else \
        0.5 * (ranked[len(ranked) // 2 - 1] + ranked[len(ranked) // 2])

    def text(x: float) -> str:
        return "never" if not np.isfinite(x) else f"{x:g}"

    return f"{text(middle)} [{text(ranked[0])}-{text(ranked[-1])}]"


def perturbed_config(config: Config, index: int,
                     perturbation: float = PERTURBATION) -> Config:
    """Perturbed run ``index``'s config: every trial starts ``perturbation`` rad (sd per joint)
    from x_d(0), its draws seeded with ``patient.seed + index`` (a config whose patient already
    varies the start keeps its own, larger spread)."""
    sd = max(float(config["patient.initial.position_sd"]), perturbation)
    return config.replace({"patient.initial.position_sd": sd,
                           "patient.seed": int(config["patient.seed"]) + index})


def iteration_spread(config: Config, mass_uncertainty: float, trials: int,
                     count: int = DEFAULT_PERTURBATIONS,
                     on_run: Callable[[IterationsToBound], None] | None = None,
                     perturbation: float = PERTURBATION) -> IterationSpread:
    """Iterations to the bound of ``count`` runs of ``config`` at ``mass_uncertainty``, each
    with initial states perturbed by ``perturbation`` (:func:`perturbed_config`, indices
    1..count); ``on_run`` sees each run's counts (progress)."""
    first: list[list[int | None]] = []
    settled: list[list[int | None]] = []
    for index in range(1, count + 1):
        result = run_trials(perturbed_config(config, index, perturbation), mass_uncertainty,
                            trials)
        its = result.iterations_to_bound()
        first.append(list(its.first))
        settled.append(list(its.settled))
        if on_run is not None:
            on_run(its)
    return IterationSpread(perturbation, first, settled)
