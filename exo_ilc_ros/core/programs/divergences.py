"""The trials of a run whose plant diverged, for a run's summary (``simulate`` in-process and a
therapy session's exercises): :mod:`..loop.divergence` over every record."""

from __future__ import annotations

from ..loop.divergence import DIVERGED, first_non_finite, trial_divergence
from ..params.config import Config
from ..session.result import RunResult
from ..session.summary import RunSummary
from ..sim.experiment import Experiment


def add_divergences(summary: RunSummary, result: RunResult, config: Config) -> None:
    """The trials whose plant diverged (a non-finite state), with the time, joint and likely
    cause, as ``summary.extra["plant_diverged"]`` (nothing if none); ``config`` is the run's
    (its mass uncertainty included)."""
    if not any(first_non_finite(r.position, r.velocity) is not None for r in result.records):
        return
    experiment = Experiment(config)
    found = [trial_divergence(experiment, r, config["joint_names"]) for r in result.records]
    summary.extra[DIVERGED] = [d.to_json() for d in found if d is not None]
