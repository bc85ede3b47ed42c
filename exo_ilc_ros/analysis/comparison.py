"""Learning laws side by side: the paper's sign law, a tuned sign law, the linear law and the
norm-optimal law.

Runs every (law, mass uncertainty) pair in-process (optionally over worker processes), then one
table (first / settled iteration per joint, final floor, peak error, learned input) and one figure
(max |e| per trial, log scale, the bound drawn).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..core.params.config import Config
from ..core.session.learning_session import run_trials
from ..core.session.summary import RunSummary
from .report import is_paper_arm


@dataclass(frozen=True)
class Variant:
    """One law to compare: a label, the config it runs with and the law's name."""

    label: str
    config: Config
    law: str


@dataclass
class ComparedRun:
    """One variant at one mass uncertainty."""

    label: str
    summary: RunSummary

    @property
    def floor(self) -> float:
        """max |e| of the last trial, over joints (rad)."""
        return float(np.max(self.summary.true_errors[-1]))

    @property
    def peak(self) -> float:
        """max |e| over every trial and joint (rad)."""
        return float(np.max(self.summary.true_errors))

    @property
    def final_feedforward(self) -> float | None:
        """max |u_ff| of the last trial, over joints (rad/s^2)."""
        ff = self.summary.max_abs_feedforward
        return None if ff is None else float(np.max(ff[-1]))


def _run(values: dict[str, Any], delta: float, trials: int, law: str) -> RunSummary:
    result = run_trials(Config(values, "compare"), delta, trials, law=law)
    return RunSummary.from_result(result)


def run_comparison(variants: Sequence[Variant], mass_uncertainties: Sequence[float],
                   trials: int, jobs: int = 1,
                   on_done: Callable[[], None] | None = None) -> list[ComparedRun]:
    """Every variant at every uncertainty, ``trials`` trials each, over ``jobs`` processes."""
    tasks = [(v, float(d)) for v in variants for d in mass_uncertainties]
    summaries: list[RunSummary] = []
    if jobs <= 1:
        for v, d in tasks:
            summaries.append(_run(v.config.values, d, trials, v.law))
            if on_done:
                on_done()
    else:
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
            futures = [pool.submit(_run, v.config.values, d, trials, v.law) for v, d in tasks]
            for future in futures:
                summaries.append(future.result())
                if on_done:
                    on_done()
    return [ComparedRun(v.label, s) for (v, _), s in zip(tasks, summaries, strict=True)]


def _fmt(x: int | None) -> str:
    return "-" if x is None else str(x)


def format_comparison(runs: Sequence[ComparedRun], joint_names: Sequence[str]) -> str:
    """One row per (law, uncertainty): first / settled per joint, floor, peak, learned input."""
    width = max([len(r.label) for r in runs] + [5]) + 2
    cell = max([len(name) + 2 for name in joint_names] + [18])  # whole joint names
    header = (f"{'law':<{width}}{'delta':>6}  "
              + "".join(f"{name:>{cell}}" for name in joint_names)
              + f"{'floor':>11}{'peak':>11}{'max|u_ff|':>11}")
    lines = ["First within / settled within the bound (trial, per joint); floor = max|e| of the "
             "last trial, peak = max|e| over all trials (rad); max|u_ff| of the last trial",
             header, "-" * len(header)]
    for r in runs:
        its = r.summary.iterations_to_bound()
        cells = "".join(f"{_fmt(f) + ' / ' + _fmt(s):>{cell}}"
                        for f, s in zip(its.first, its.settled, strict=True))
        ff = r.final_feedforward
        lines.append(f"{r.label:<{width}}{r.summary.mass_uncertainty:>6.2f}  {cells}"
                     f"{r.floor:>11.2e}{r.peak:>11.2e}"
                     + (f"{ff:>11.3g}" if ff is not None else f"{'':>11}"))
    lines.append("('-': never within / not within at the last trial"
                 + ("; paper, joint 1: 35 / 96 / 101 at 5 / 10 / 15 %)"
                    if is_paper_arm(joint_names) else ")"))
    return "\n".join(lines)


def plot_comparison(runs: Sequence[ComparedRun], joint_names: Sequence[str],
                    path: Path | str) -> None:
    """Max |e| per trial: one row per uncertainty, one column per joint, one line per law."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    deltas = sorted({r.summary.mass_uncertainty for r in runs})
    labels = list(dict.fromkeys(r.label for r in runs))
    joints = len(joint_names)
    fig, axes = plt.subplots(len(deltas), joints,
                             figsize=(4.2 * joints, 2.8 * len(deltas) + 0.4),
                             sharex=True, squeeze=False, layout="constrained")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for row, delta in enumerate(deltas):
        for j in range(joints):
            ax = axes[row][j]
            for r in runs:
                if r.summary.mass_uncertainty != delta:
                    continue
                errors = r.summary.true_errors[:, j]
                trials = np.arange(1, len(errors) + 1)
                ax.semilogy(trials, errors, lw=1.2, label=r.label,
                            color=colours[labels.index(r.label) % len(colours)])
            bound = runs[0].summary.error_bound
            ax.axhline(bound, color="k", ls="--", lw=0.8, label=f"bound {bound:g} rad")
            ax.grid(True, which="both", alpha=0.3)
            if row == 0:
                ax.set_title(joint_names[j])
            if j == 0:
                ax.set_ylabel(f"max |e| (rad), δ = {delta:.0%}")
            if row == len(deltas) - 1:
                ax.set_xlabel("trial")
    # One legend below the panels, never over a curve.
    fig.legend(*axes[0][0].get_legend_handles_labels(), loc="outside lower center",
               ncols=len(labels) + 1, fontsize=8, frameon=False)
    fig.suptitle("Max tracking error per trial: " + ", ".join(labels))
    fig.savefig(path, dpi=120)
    plt.close(fig)
