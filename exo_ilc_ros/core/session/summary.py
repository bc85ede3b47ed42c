"""A run as its tables show it (max |e|, |u_ff|, |effort| per trial and joint), whichever way it
ran: in-process, through the graph, or read back from a bag or a JSON export."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..convergence.bound import IterationsToBound, iterations_to_bound
from ..person.cuffs import CUFF_METRICS, CUFFS, cuff_metrics
from .abort import ABORT_STOP_KEY
from .result import RunResult

CUFF_LIMIT_ABORTS = "cuff_limit_aborts"
"""A run's ``extra`` (and JSON) key: the trials the cuff-force limit aborted (a person
strapped in; of ``aborted_trials``), absent when none did."""


@dataclass
class RunSummary:
    """One run as the tables show it: max |e| per trial and joint, plus what was learned."""

    mass_uncertainty: float
    law: str
    error_bound: float
    max_abs_error: np.ndarray
    max_abs_feedforward: np.ndarray | None = None
    max_abs_effort: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    true_max_abs_error: np.ndarray | None = None
    """The true max |e| (the plant's state) where the sensors made the measured
    ``max_abs_error`` differ from it (the virtual patient); None: they are the same."""
    cuff_forces: np.ndarray | None = None
    """A person strapped in cuffs: per trial and cuff (upper arm, forearm) the peak and RMS
    |force| (N) and the peak and RMS |torque| (N m) on the person, shape (K, 2, 4)
    (:func:`~exo_ilc_ros.core.person.cuffs.cuff_metrics`); None: no person."""

    @classmethod
    def from_result(cls, result: RunResult) -> RunSummary:
        """From an in-process run (with its live changes, :func:`live_changes`)."""
        measured = any(r.true_position is not None for r in result.records)
        summary = cls(result.mass_uncertainty, result.law, result.error_bound,
                      result.max_abs_errors, result.max_abs_feedforward, result.max_abs_effort,
                      true_max_abs_error=result.true_max_abs_errors() if measured else None)
        if result.records and all(r.cuff_wrench is not None for r in result.records):
            summary.cuff_forces = np.array([cuff_metrics(np.asarray(r.cuff_wrench))
                                            for r in result.records])
        summary.extra.update(live_changes(result.applied, result.law))
        if result.aborted:
            summary.extra["aborted_trials"] = list(result.aborted)
        if result.stop_message:
            summary.extra[ABORT_STOP_KEY] = result.stop_message
        return summary

    @property
    def true_errors(self) -> np.ndarray:
        """The true max |e| table (the measured one when they are the same)."""
        return self.max_abs_error if self.true_max_abs_error is None \
            else self.true_max_abs_error

    def iterations_to_bound(self) -> IterationsToBound:
        """First and settled trial per joint, of the true max |e|; a trial a bag did not hold
        (``extra["sources"]`` ``missing``: left out as damaged) counts neither way."""
        sources = self.extra.get("sources")
        known = None if sources is None else np.array([s != "missing" for s in sources])
        return iterations_to_bound(self.true_errors, self.error_bound, known)

    def to_json(self) -> dict[str, Any]:
        """The ``runs[]`` entry of the JSON export."""
        its = self.iterations_to_bound()
        trials = []
        for k, row in enumerate(self.max_abs_error):
            entry: dict[str, Any] = {"trial": k + 1, "max_abs_error": [float(x) for x in row],
                                     "true_max_abs_error": [float(x)
                                                            for x in self.true_errors[k]]}
            if self.max_abs_feedforward is not None:
                entry["max_abs_feedforward"] = [float(x) for x in self.max_abs_feedforward[k]]
            if self.max_abs_effort is not None:
                entry["max_abs_effort"] = [float(x) for x in self.max_abs_effort[k]]
            if self.cuff_forces is not None:
                entry["cuff_forces"] = {cuff: dict(zip(CUFF_METRICS, map(float, row),
                                                       strict=True))
                                        for cuff, row in zip(CUFFS, self.cuff_forces[k],
                                                             strict=True)}
            trials.append(entry)
        out = {"mass_uncertainty": self.mass_uncertainty, "law": self.law,
               "error_bound": self.error_bound, "trials": trials,
               "iterations_to_bound": {"first": its.first, "settled": its.settled}}
        out.update(self.extra)
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunSummary:
        """Inverse of :meth:`to_json`."""
        trials = data["trials"]

        def table(key: str) -> np.ndarray | None:
            if not trials or key not in trials[0]:
                return None
            return np.array([t[key] for t in trials], dtype=float)

        errors = table("max_abs_error")
        true = table("true_max_abs_error")
        if true is not None and errors is not None and np.array_equal(true, errors):
            true = None
        cuffs = None
        if trials and "cuff_forces" in trials[0]:
            cuffs = np.array([[[t["cuff_forces"][c][m] for m in CUFF_METRICS] for c in CUFFS]
                              for t in trials], dtype=float)
        return cls(float(data["mass_uncertainty"]), str(data["law"]),
                   float(data.get("error_bound", 0.005)),
                   errors if errors is not None else np.zeros((0, 0)),
                   table("max_abs_feedforward"), table("max_abs_effort"),
                   true_max_abs_error=true, cuff_forces=cuffs)


def law_segments(first_law: str, changes: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """``[{"from_trial": 1, "law": "sign"}, {"from_trial": 7, "law": "linear"}]``: the law each
    trial ran, from the run's first law and its live ``changes`` (:func:`live_changes`'
    entries); empty when no change switched the law."""
    segments = [{"from_trial": 1, "law": str(first_law)}]
    for change in sorted(changes, key=lambda c: int(c["trial"])):
        if change["parameter"] == "law" and change["value"] != segments[-1]["law"]:
            segments.append({"from_trial": int(change["trial"]), "law": str(change["value"])})
    return segments if len(segments) > 1 else []


def live_changes(applied: Mapping[int, Mapping[str, Any]], first_law: str,
                 node: str = "ilc_supervisor") -> dict[str, Any]:
    """The ``extra`` entries of a run's live parameter changes (``applied``: the first trial
    run with them -> values): ``live_changes`` and ``laws`` (:func:`law_segments`); empty
    without changes."""
    if not applied:
        return {}
    changes = [{"trial": int(k), "node": node, "parameter": str(name), "value": value}
               for k, values in sorted(applied.items()) for name, value in sorted(values.items())]
    out: dict[str, Any] = {"live_changes": changes}
    laws = law_segments(first_law, changes)
    if laws:
        out["laws"] = laws
    return out
