"""Per-trial tables and the JSON export shared by ``exo-ilc simulate``, ``run`` and ``analyze``."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .core.experiment import IterationsToBound, RunResult, iterations_to_bound

PAPER_FIRST_JOINT1 = {0.05: 35, 0.10: 96, 0.15: 101}
"""Iterations to the 0.005 rad bound the paper reports for joint 1; joints 2-3: within 20."""
PAPER_OTHER_JOINTS_WITHIN = 20


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

    @classmethod
    def from_result(cls, result: RunResult) -> RunSummary:
        """From an in-process run."""
        return cls(result.mass_uncertainty, result.law, result.error_bound,
                   result.max_abs_errors, result.max_abs_feedforward, result.max_abs_effort)

    def iterations_to_bound(self) -> IterationsToBound:
        """First and settled trial per joint."""
        return iterations_to_bound(self.max_abs_error, self.error_bound)

    def to_json(self) -> dict[str, Any]:
        """The ``runs[]`` entry of the JSON export."""
        its = self.iterations_to_bound()
        trials = []
        for k, row in enumerate(self.max_abs_error):
            entry: dict[str, Any] = {"trial": k + 1, "max_abs_error": [float(x) for x in row]}
            if self.max_abs_feedforward is not None:
                entry["max_abs_feedforward"] = [float(x) for x in self.max_abs_feedforward[k]]
            if self.max_abs_effort is not None:
                entry["max_abs_effort"] = [float(x) for x in self.max_abs_effort[k]]
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
        return cls(float(data["mass_uncertainty"]), str(data["law"]),
                   float(data.get("error_bound", 0.005)),
                   errors if errors is not None else np.zeros((0, 0)),
                   table("max_abs_feedforward"), table("max_abs_effort"))


def write_json(path: Path | str, config_values: dict[str, Any],
               runs: Sequence[RunSummary]) -> None:
    """``{"config": ..., "runs": [...]}`` to ``path``."""
    document = {"config": config_values, "runs": [r.to_json() for r in runs]}
    Path(path).write_text(json.dumps(document, indent=1) + "\n")


def _fmt(x: int | None) -> str:
    return "-" if x is None else str(x)


def format_trial_table(runs: Sequence[RunSummary], joint_names: Sequence[str]) -> str:
    """Max |e| (rad) per trial: one column group per run, one column per joint."""
    n = len(joint_names)
    head1 = f"{'trial':>5} "
    head2 = f"{'':>5} "
    for r in runs:
        title = f"{r.law} d={r.mass_uncertainty:g}"
        head1 += f"| {title:^{n * 11}}"
        head2 += "| " + "".join(f"{'e' + str(j + 1):>10} " for j in range(n))
    lines = [head1, head2, "-" * len(head2)]
    count = max(len(r.max_abs_error) for r in runs)
    for k in range(count):
        line = f"{k + 1:>5} "
        for r in runs:
            if k < len(r.max_abs_error):
                cells = [f"{x:10.3e}" + ("*" if x > r.error_bound else " ")
                         for x in r.max_abs_error[k]]
                line += "| " + "".join(cells)
            else:
                line += "| " + " " * (n * 11)
        lines.append(line)
    lines.append("(* above the bound)")
    return "\n".join(lines)


def format_iterations(runs: Sequence[RunSummary], joint_names: Sequence[str]) -> str:
    """Iterations to the bound per joint (first / settled) beside the paper's numbers."""
    lines = [f"Iterations to the bound, first within / settled within (paper: joint 1 "
             f"35/96/101 at 5/10/15 %, joints 2-3 within {PAPER_OTHER_JOINTS_WITHIN})"]
    header = f"{'law':<8}{'delta':>7}  " + "".join(f"{name[:18]:>20}" for name in joint_names)
    lines += [header + f"{'paper joint 1':>15}", "-" * (len(header) + 15)]
    for r in runs:
        its = r.iterations_to_bound()
        cells = "".join(f"{_fmt(f) + ' / ' + _fmt(s):>20}"
                        for f, s in zip(its.first, its.settled, strict=True))
        paper = PAPER_FIRST_JOINT1.get(round(r.mass_uncertainty, 4))
        lines.append(f"{r.law:<8}{r.mass_uncertainty:>7.3f}  {cells}{_fmt(paper):>15}")
    lines.append("('-': never within the bound / not within at the last trial)")
    return "\n".join(lines)
