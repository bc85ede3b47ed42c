"""Per-trial tables and the JSON export shared by ``exo-ilc simulate``, ``run`` and ``analyze``."""

from __future__ import annotations

import functools
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..core.convergence.growth import DEFAULT_WINDOW, MIN_TRIALS, fit_growth, held_at_limit
from ..core.params.config import load_config
from ..core.programs.spread import IterationSpread
from ..core.session.summary import RunSummary
from .loop import format_growth

PAPER_FIRST_JOINT1 = {0.05: 35, 0.10: 96, 0.15: 101}
"""Iterations to the 0.005 rad bound the paper reports for joint 1; joints 2-3: within 20."""
PAPER_OTHER_JOINTS_WITHIN = 20


@functools.cache
def _paper_joint_names() -> tuple[str, ...]:
    return tuple(load_config()["joint_names"])


def is_paper_arm(joint_names: Sequence[str]) -> bool:
    """The paper's iterations apply: the arm's joints are the paper arm's (the shipped
    config's ``joint_names``), not a URDF arm's or another cone arm's."""
    return tuple(joint_names) == _paper_joint_names()


def write_json(path: Path | str, config_values: dict[str, Any],
               runs: Sequence[RunSummary]) -> None:
    """``{"config": ..., "runs": [...]}`` to ``path``."""
    document = {"config": config_values, "runs": [r.to_json() for r in runs]}
    Path(path).write_text(json.dumps(document, indent=1) + "\n")


def _fmt(x: int | None) -> str:
    return "-" if x is None else str(x)


TABLE_QUANTITIES = {"error": "max |e| (rad)",
                    "feedforward": "max |u_ff| (rad/s^2, learned feed-forward)",
                    "effort": "max |effort| (N m)"}
"""What :func:`format_trial_table` can show, by its title."""


def exercise_of(run: RunSummary) -> str | None:
    """The therapy exercise ``run`` is (None: not a therapy run)."""
    therapy = run.extra.get("therapy")
    return str(therapy.get("exercise")) if isinstance(therapy, dict) else None


def run_title(run: RunSummary) -> str:
    """``sign d=0.05``, or ``reach_and_return: sign d=0.05`` for a therapy exercise."""
    exercise = exercise_of(run)
    head = f"{exercise}: " if exercise else ""
    return f"{head}{run.law} d={run.mass_uncertainty:g}"


def _table_of(run: RunSummary, quantity: str) -> np.ndarray | None:
    if quantity == "error":
        return run.true_errors
    return run.max_abs_feedforward if quantity == "feedforward" else run.max_abs_effort


def format_trial_table(runs: Sequence[RunSummary], joint_names: Sequence[str],
                       quantity: str = "error", labels: Sequence[str] | None = None) -> str:
    """Max |e| (rad) per trial: one column group per run, one column per joint headed by its
    name (the true max |e|, titled so, for runs whose sensors measured something else).

    ``quantity`` "feedforward" or "effort" shows max |u_ff| or max |effort| instead. ``labels``
    (e.g. bag names) head the column groups instead of law and uncertainty."""
    title_q = TABLE_QUANTITIES[quantity]
    tables = [_table_of(r, quantity) for r in runs]
    columns = [max(10, len(name)) for name in joint_names]
    head1 = f"{'trial':>5} "
    head2 = f"{'':>5} "
    titles = [labels[i] if labels is not None else run_title(r) for i, r in enumerate(runs)]
    # a whole label over each group
    widths = [max(sum(columns) + len(columns), len(title)) for title in titles]
    for title, width in zip(titles, widths, strict=True):
        head1 += f"| {title:^{width}}"
        head2 += "| " + "".join(f"{name:>{c}} " for name, c in zip(joint_names, columns,
                                                                    strict=True)).ljust(width)
    if quantity == "error" and any(r.true_max_abs_error is not None for r in runs):
        title_q = ("true max |e| (rad): the plant's state; the controller measured other "
                   "values (max_abs_error in the JSON)")
    lines = [title_q, head1, head2, "-" * len(head2)]
    count = max(len(r.max_abs_error) for r in runs)
    for k in range(count):
        line = f"{k + 1:>5} "
        for r, table, width in zip(runs, tables, widths, strict=True):
            if table is not None and k < len(table):
                flag = quantity == "error"
                cells = [f"{x:{c}.3e}" + ("*" if flag and x > r.error_bound else " ")
                         for x, c in zip(table[k], columns, strict=True)]
                line += "| " + "".join(cells).ljust(width)
            else:
                line += "| " + " " * width
        switched = [f"{title}: {segment['law']} from here" for r, title in zip(runs, titles,
                                                                          strict=True)
                    for segment in r.extra.get("laws", [])[1:]
                    if int(segment["from_trial"]) == k + 1]
        lines.append(line + ("  <- " + "; ".join(switched) if switched else ""))
    if quantity == "error":
        lines.append("(* above the bound)")
    return "\n".join(lines)


def format_run_events(runs: Sequence[RunSummary], labels: Sequence[str] | None = None) -> str:
    """The live parameter changes (with the first trial run with each) and the trials run
    again (watchdog trip, lost samples, ...) of every run; "" when there were none."""
    lines = []
    for i, r in enumerate(runs):
        title = labels[i] if labels is not None else run_title(r)
        for change in r.extra.get("live_changes", []):
            lines.append(f"{title}: live change from trial {change['trial']}: "
                         f"{change.get('node', 'ilc_supervisor')} {change['parameter']} = "
                         f"{json.dumps(change['value'])}")
        for again in r.extra.get("reruns", []):
            lines.append(f"{title}: trial {again['trial']} was run again ({again['reason']}: "
                         "the attempt was discarded, the trial repeated with the same "
                         "feed-forward)")
    return "\n".join(lines)


def format_long_run(runs: Sequence[RunSummary], joint_names: Sequence[str],
                    window: int = DEFAULT_WINDOW, limit: np.ndarray | None = None) -> str:
    """Per run: max |u_ff| and max |effort| at the last trial, and whether the learned input
    keeps growing (:func:`~exo_ilc_ros.core.convergence.growth.fit_growth` over the last ``window``
    trials, at most the second half of the run so that the first trials' learning is not
    mistaken for growth); a joint at ``limit`` (``feedforward_limit``, None: none) is reported
    at its limit (:func:`~exo_ilc_ros.core.convergence.growth.held_at_limit`)."""
    lines = ["Learned input at the last trial and its growth (max |u_ff| per joint, rad/s^2; "
             "max |effort|, N m)"]
    for r in runs:
        exercise = exercise_of(r)
        head = ((f"{exercise}: " if exercise else "")
                + f"{law_label(r):<8}{r.mass_uncertainty:>7.3f}  ")
        if r.max_abs_feedforward is None or len(r.max_abs_feedforward) == 0:
            lines.append(head + "no feed-forward recorded")
            continue
        uff = " ".join(f"{x:.3g}" for x in r.max_abs_feedforward[-1])
        effort = ("" if r.max_abs_effort is None else
                  "  |effort| " + " ".join(f"{x:.3g}" for x in r.max_abs_effort[-1]))
        lines.append(head + f"|u_ff| {uff}{effort}")
        span = min(window, max(len(r.max_abs_feedforward) // 2, MIN_TRIALS))
        lines.append(" " * 17 + format_growth(fit_growth(r.max_abs_feedforward, span),
                                              joint_names,
                                              held_at_limit(r.max_abs_feedforward, limit)))
    return "\n".join(lines)


def format_iterations(runs: Sequence[RunSummary], joint_names: Sequence[str],
                      labels: Sequence[str] | None = None) -> str:
    """Iterations to the bound per joint (first / settled), one column per joint named by the
    arm's ``joint_names``, beside the paper's numbers for the paper's arm only
    (:func:`is_paper_arm`; not for therapy exercises either: another movement than the
    paper's); ``labels`` (e.g. bag names) in a first column, one per run, else the exercise for
    a therapy run."""
    therapy = all(exercise_of(r) for r in runs)
    if labels is None and therapy:
        labels = [str(exercise_of(r)) for r in runs]
    paper_column = not therapy and is_paper_arm(joint_names)
    lines = ["Iterations to the bound, first within / settled within"
             + (f" (paper: joint 1 35/96/101 at 5/10/15 %, joints 2-3 within "
                f"{PAPER_OTHER_JOINTS_WITHIN})" if paper_column else "")]
    w = max([8] + [len(r.law) + 1 for r in runs])  # 8 for sign / linear, wider for norm_optimal
    cell = max([len(name) + 2 for name in joint_names] + [20])
    first = max([len(label) + 2 for label in labels] + [5]) if labels is not None else 0
    column = "exercise" if therapy and labels is not None else "bag" if labels else ""
    header = (f"{column:<{first}}{'law':<{w}}{'delta':>7}  "
              + "".join(f"{name:>{cell}}" for name in joint_names))
    paper_width = 15 if paper_column else 0
    lines += [header + (f"{'paper joint 1':>15}" if paper_column else ""),
              "-" * (len(header) + paper_width)]
    for i, r in enumerate(runs):
        its = r.iterations_to_bound()
        cells = "".join(f"{_fmt(f) + ' / ' + _fmt(s):>{cell}}"
                        for f, s in zip(its.first, its.settled, strict=True))
        paper = PAPER_FIRST_JOINT1.get(round(r.mass_uncertainty, 4))
        label = labels[i] if labels is not None else ""
        lines.append(f"{label:<{first}}{law_label(r):<{w}}{r.mass_uncertainty:>7.3f}  {cells}"
                     + (f"{_fmt(paper):>15}" if paper_column else ""))
    lines.append("('-': never within the bound / not within at the last trial)")
    if any("spread" in r.extra for r in runs):
        lines.append("")
        lines.append(format_spread(runs, joint_names))
    elif any(r.law == "sign" for r in runs) and not therapy:
        lines.append("(one run each: the sign law amplifies last-bit differences, so a count can "
                     "move by several trials; --spread 20 shows median [min-max] over 20 runs "
                     "from initial states perturbed by 1e-12 rad)")
    return "\n".join(lines)


def law_label(run: RunSummary) -> str:
    """The law, or ``sign->linear`` when a live change switched it (``extra["laws"]``)."""
    laws = run.extra.get("laws")
    if not laws:
        return run.law
    names = [str(item["law"]) for item in laws]
    return "->".join(n for k, n in enumerate(names) if k == 0 or n != names[k - 1])


def format_spread(runs: Sequence[RunSummary], joint_names: Sequence[str]) -> str:
    """The iterations to the bound of each run's perturbed runs (``extra["spread"]``, from
    :func:`~exo_ilc_ros.core.programs.spread.iteration_spread`): median [min-max] per joint."""
    spreads = [r.extra["spread"] for r in runs if "spread" in r.extra]
    count = {s["count"] for s in spreads}
    size = {s["perturbation"] for s in spreads}
    lines = [f"The same over {'/'.join(map(str, sorted(count)))} runs from initial states "
             f"perturbed by {'/'.join(f'{x:g}' for x in sorted(size))} rad (sd per joint, every "
             "trial): median [min-max]; the single run above starts exactly at x_d(0)"]
    w = max([8] + [len(r.law) + 1 for r in runs])
    rows = []
    for r in runs:
        data = r.extra.get("spread")
        if data is not None:
            spread = IterationSpread(float(data["perturbation"]), data["first"], data["settled"])
            rows.append((r, [spread.cell(j) for j in range(len(joint_names))]))
    cell = max([len(name) for name in joint_names]
               + [len(text) for _, cells in rows for text in cells]) + 2
    header = f"{'law':<{w}}{'delta':>7}  " + "".join(f"{name:>{cell}}" for name in joint_names)
    lines += [header, "-" * len(header)]
    for r, cells in rows:
        lines.append(f"{r.law:<{w}}{r.mass_uncertainty:>7.3f}  "
                     + "".join(f"{text:>{cell}}" for text in cells))
    lines.append("(never: not within the bound by the last trial)")
    return "\n".join(lines)


CUFF_COLUMNS = ("peak F", "RMS F", "peak T", "RMS T")
"""The cuff table's columns per cuff (N, N, N m, N m: ``core.person.cuffs.CUFF_METRICS``)."""


def format_cuff_table(runs: Sequence[RunSummary], labels: Sequence[str] | None = None) -> str:
    """The cuff forces on the person per trial (a person strapped in, ``cuff_forces``): per
    run and cuff the peak and RMS |force| (N) and the peak and RMS |torque| (N m); the runs
    without a person are left out, and "" when no run has one (no empty columns)."""
    shown = [(i, r) for i, r in enumerate(runs) if r.cuff_forces is not None]
    if not shown:
        return ""
    cell = 9
    cuffs = ("upper arm", "forearm")
    group = len(cuffs) * len(CUFF_COLUMNS) * cell
    titles = [labels[i] if labels is not None else run_title(r) for i, r in shown]
    widths = [max(group, len(title)) for title in titles]
    head1, head2, head3 = f"{'trial':>5} ", f"{'':>5} ", f"{'':>5} "
    for title, width in zip(titles, widths, strict=True):
        head1 += f"| {title:^{width}}"
        head2 += "| " + "".join(f"{c:^{len(CUFF_COLUMNS) * cell}}" for c in cuffs).ljust(width)
        head3 += "| " + "".join(f"{c:>{cell}}" for _ in cuffs for c in CUFF_COLUMNS).ljust(width)
    lines = ["cuff forces on the person per trial (peak / RMS |F| in N, |T| in N m)", head1,
             head2, head3, "-" * len(head3)]
    count = max(len(r.cuff_forces) for _, r in shown if r.cuff_forces is not None)
    for k in range(count):
        line = f"{k + 1:>5} "
        for (_, r), width in zip(shown, widths, strict=True):
            table = r.cuff_forces
            if table is not None and k < len(table):
                line += "| " + "".join(f"{x:{cell}.1f}" if np.isfinite(x) else f"{'-':>{cell}}"
                                       for x in table[k].ravel()).ljust(width)
            else:
                line += "| " + " " * width
        lines.append(line)
    return "\n".join(lines)
