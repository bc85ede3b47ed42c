"""The paper's figures from run tables and recorded trials (matplotlib, no display needed).

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot state), so callers
and tests can inspect the axes and lines before or instead of saving.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..bag.run import TrialData
from ..core.session.summary import RunSummary
from .report import PAPER_FIRST_JOINT1, PAPER_OTHER_JOINTS_WITHIN, is_paper_arm


def run_label(run: RunSummary) -> str:
    """``sign, 5 % mass uncertainty``."""
    return f"{run.law}, {100 * run.mass_uncertainty:g} % mass uncertainty"


def convergence_figure(runs: Sequence[RunSummary], joint_names: Sequence[str],
                       labels: Sequence[str] | None = None) -> Figure:
    """Figures 5-7 of the paper: max |e_j| per iteration, one subplot per joint (any number),
    one curve per run, the bound drawn (dashed), log y axis; the titles quote the paper's
    iterations for the paper's arm only (:func:`.report.is_paper_arm`)."""
    labels = list(labels) if labels is not None else [run_label(r) for r in runs]
    n = len(joint_names)
    paper_arm = is_paper_arm(joint_names)
    columns = 1 if max((len(label) for label in labels), default=0) > 40 else 2
    legend_rows = -(-(len(runs) + 1) // columns)
    fig = Figure(figsize=(6.4, 2.6 * n + 0.2 * legend_rows + 0.2), layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    bound = runs[0].error_bound if runs else 0.005
    for j, ax in enumerate(axes):
        for run, label in zip(runs, labels, strict=True):
            trials = np.arange(1, len(run.true_errors) + 1)
            ax.semilogy(trials, run.true_errors[:, j], marker=".", markersize=3,
                        linewidth=1.0, label=label)
        ax.axhline(bound, color="k", linestyle="--", linewidth=0.8,
                   label=f"bound {bound:g} rad")
        paper = ", ".join(f"{100 * d:g} %: {k}" for d, k in PAPER_FIRST_JOINT1.items()) \
            if j == 0 else f"within {PAPER_OTHER_JOINTS_WITHIN}"
        quoted = f"; paper: {paper}" if paper_arm else ""
        ax.set_title(f"Joint {j + 1} ({joint_names[j]}){quoted}", fontsize=9)
        ax.set_ylabel(f"max |e{j + 1}| (rad)")
        ax.grid(True, which="both", linewidth=0.3)
    axes[-1].set_xlabel("iteration (trial)")
    # Below the panels, never over a curve (one entry per run, so runs can be told apart).
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=columns,
               fontsize=7, frameon=False)
    return fig


def tracking_figure(trial: TrialData, joint_names: Sequence[str], title: str = "",
                    bound: float | None = None) -> Figure:
    """One trial: q vs q_d, the error (with the bound +-``bound`` dashed, if given), the effort
    commanded and the feed-forward, one column per joint."""
    n = len(joint_names)
    fig = Figure(figsize=(3.4 * n, 8.0), layout="constrained")
    axes = fig.subplots(4, n, sharex=True, squeeze=False)
    t = trial.time
    effort = trial.command if not np.all(np.isnan(trial.command)) else \
        np.vstack([trial.effort[1:], np.full((1, n), np.nan)])
    for j, name in enumerate(joint_names):
        ax = axes[0, j]
        ax.plot(t, trial.reference_position[:, j], "k--", linewidth=1.0, label="q_d")
        ax.plot(t, trial.position[:, j], linewidth=1.0, label="q")
        ax.set_title(name, fontsize=9)
        axes[1, j].plot(t, trial.error[:, j], linewidth=1.0, label="e")
        if bound is not None:
            for sign in (1, -1):
                axes[1, j].axhline(sign * bound, color="k", linestyle="--", linewidth=0.8,
                                   label=f"bound ±{bound:g} rad" if sign > 0 else None)
        axes[2, j].plot(t, effort[:, j], linewidth=1.0)
        if trial.feedforward is not None:
            axes[3, j].plot(t, trial.feedforward[:, j], linewidth=1.0)
        axes[3, j].set_xlabel("t (s)")
        for row in axes[:, j]:
            row.grid(True, linewidth=0.3)
    axes[0, 0].legend(fontsize=7)
    if bound is not None:
        axes[1, 0].legend(fontsize=7, loc="best")
    for row, label in enumerate(("q (rad)", "e = q_d - q (rad)", "effort (N m)",
                                 "u_ff (rad/s^2)")):
        axes[row, 0].set_ylabel(label)
    fig.suptitle(title or f"Trial {trial.trial}", fontsize=10)
    return fig


def save(fig: Figure, path: Path | str) -> Path:
    """Write ``fig`` (format from the suffix) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path
