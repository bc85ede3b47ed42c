"""Per-trial tables and the JSON export shared by ``exo-ilc simulate``, ``run`` and ``analyze``."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .core.experiment import IterationsToBound, iterations_to_bound
from .core.growth import DEFAULT_WINDOW, MIN_TRIALS, fit_growth, format_growth
from .core.session import RunResult

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


TABLE_QUANTITIES = {"error": ("e", "max |e| (rad)"),
                    "feedforward": ("uff", "max |u_ff| (rad/s^2, learned feed-forward)"),
                    "effort": ("Q", "max |effort| (N m)")}
"""What :func:`format_trial_table` can show: column prefix and title."""


def _table_of(run: RunSummary, quantity: str) -> np.ndarray | None:
    if quantity == "error":
        return run.max_abs_error
    return run.max_abs_feedforward if quantity == "feedforward" else run.max_abs_effort


def format_trial_table(runs: Sequence[RunSummary], joint_names: Sequence[str],
                       quantity: str = "error") -> str:
    """Max |e| (rad) per trial: one column group per run, one column per joint.

    ``quantity`` "feedforward" or "effort" shows max |u_ff| or max |effort| instead."""
    prefix, title_q = TABLE_QUANTITIES[quantity]
    tables = [_table_of(r, quantity) for r in runs]
    n = len(joint_names)
    head1 = f"{'trial':>5} "
    head2 = f"{'':>5} "
    for r in runs:
        title = f"{r.law} d={r.mass_uncertainty:g}"
        head1 += f"| {title:^{n * 11}}"
        head2 += "| " + "".join(f"{prefix + str(j + 1):>10} " for j in range(n))
    lines = ([title_q] if quantity != "error" else []) + [head1, head2, "-" * len(head2)]
    count = max(len(r.max_abs_error) for r in runs)
    for k in range(count):
        line = f"{k + 1:>5} "
        for r, table in zip(runs, tables, strict=True):
            if table is not None and k < len(table):
                flag = quantity == "error"
                cells = [f"{x:10.3e}" + ("*" if flag and x > r.error_bound else " ")
                         for x in table[k]]
                line += "| " + "".join(cells)
            else:
                line += "| " + " " * (n * 11)
        lines.append(line)
    if quantity == "error":
        lines.append("(* above the bound)")
    return "\n".join(lines)


def format_long_run(runs: Sequence[RunSummary], joint_names: Sequence[str],
                    window: int = DEFAULT_WINDOW) -> str:
    """Per run: max |u_ff| and max |effort| at the last trial, and whether the learned input
    keeps growing (:func:`~exo_ilc_ros.core.growth.fit_growth` over the last ``window``
    trials, at most the second half of the run so that the first trials' learning is not
    mistaken for growth)."""
    lines = ["Learned input at the last trial and its growth (max |u_ff| per joint, rad/s^2; "
             "max |effort|, N m)"]
    for r in runs:
        head = f"{r.law:<8}{r.mass_uncertainty:>7.3f}  "
        if r.max_abs_feedforward is None or len(r.max_abs_feedforward) == 0:
            lines.append(head + "no feed-forward recorded")
            continue
        uff = " ".join(f"{x:.3g}" for x in r.max_abs_feedforward[-1])
        effort = ("" if r.max_abs_effort is None else
                  "  |effort| " + " ".join(f"{x:.3g}" for x in r.max_abs_effort[-1]))
        lines.append(head + f"|u_ff| {uff}{effort}")
        span = min(window, max(len(r.max_abs_feedforward) // 2, MIN_TRIALS))
        lines.append(" " * 17 + format_growth(fit_growth(r.max_abs_feedforward, span),
                                              joint_names))
    return "\n".join(lines)


def format_iterations(runs: Sequence[RunSummary], joint_names: Sequence[str]) -> str:
    """Iterations to the bound per joint (first / settled) beside the paper's numbers."""
    lines = [f"Iterations to the bound, first within / settled within (paper: joint 1 "
             f"35/96/101 at 5/10/15 %, joints 2-3 within {PAPER_OTHER_JOINTS_WITHIN})"]
    w = max([8] + [len(r.law) + 1 for r in runs])  # 8 for sign / linear, wider for norm_optimal
    header = f"{'law':<{w}}{'delta':>7}  " + "".join(f"{name[:18]:>20}" for name in joint_names)
    lines += [header + f"{'paper joint 1':>15}", "-" * (len(header) + 15)]
    for r in runs:
        its = r.iterations_to_bound()
        cells = "".join(f"{_fmt(f) + ' / ' + _fmt(s):>20}"
                        for f, s in zip(its.first, its.settled, strict=True))
        paper = PAPER_FIRST_JOINT1.get(round(r.mass_uncertainty, 4))
        lines.append(f"{r.law:<{w}}{r.mass_uncertainty:>7.3f}  {cells}{_fmt(paper):>15}")
    lines.append("('-': never within the bound / not within at the last trial)")
    return "\n".join(lines)
