"""The loop analysis as a user reads it: the trial-to-trial factor per joint and frequency
(``exo-ilc analyze-loop``, its figure), the growth check of a long run and the norm-optimal
law's robustness check, from the numbers ``core.convergence``, ``core.convergence.growth`` and
``core.learning.norm_optimal`` compute."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..core.convergence.factors import LoopAnalysis, bands_above_one
from ..core.convergence.growth import MIN_TRIALS, GrowthFit
from ..core.convergence.norm_optimal_robustness import ROBUST_TOLERANCE, Robustness


def format_analysis(analysis: LoopAnalysis) -> str:
    """The worst factor and the bands above 1 per joint, without and with the Q-filter."""
    a = analysis
    lines = [f"law {a.law}, memory {a.memory.value}, delta {a.mass_uncertainty:g}, "
             f"period {a.period:g} s (Nyquist {a.nyquist_hz:g} Hz)"]
    if a.qfilter is not None:
        lines.append(f"Q-filter: Butterworth order {a.qfilter.order}, cut-off "
                     f"{a.qfilter.cutoff_hz:g} Hz, zero-phase (sosfiltfilt, even padding)")
    else:
        lines.append("Q-filter: off")
    if a.forgetting is not None:
        lines.append(f"assist-as-needed: forgetting f = {a.forgetting:g}; |F| is the worst of "
                     "inside the deadband (f |m|) and outside it (|F - (1 - f) m|)")
    variants = [("no Q", False)] + ([("with Q", True)] if a.qfilter is not None else [])
    for label, filtered in variants:
        lines.append(f"  {label}:")
        for j in a.joints:
            value, k = j.worst(filtered)
            data = j.filtered if filtered and j.filtered is not None else j.unfiltered
            bands = bands_above_one(a.frequency_hz, data)
            text = ", ".join(f"{b.low_hz:.2f}-{b.high_hz:.2f} Hz" for b in bands) or "none"
            lines.append(f"    {j.joint:<20} max |F| {value:.5f} at {a.frequency_hz[k]:6.2f} Hz"
                         f"   |F| > 1: {text}")
            check = j.lifted_filtered if filtered else j.lifted
            if check is not None:
                rate = check.growth_per_trial
                grows = (f"log ||F^K|| / K {rate:+.5f} per trial" if np.isfinite(rate)
                         else "F^K = 0")
                lines.append(f"    {'':<20} lifted trial: spectral radius "
                             f"{check.spectral_radius:.5f}, K = {check.trials}: {grows}")
        worst = a.worst(filtered)
        verdict = ("converges (contraction at every frequency)" if worst < 1.0 else
                   "bounded (|F| = 1 only where the law does not learn: nothing is amplified)"
                   if worst <= 1.0 + 1e-9 else
                   f"grows by up to {100.0 * (worst - 1.0):.3g} % per trial in the band above")
        lines.append(f"    worst {worst:.5f}: {verdict}")
    return "\n".join(lines)


def plot_analysis(analysis: LoopAnalysis, path: str) -> None:
    """|F| against frequency per joint, without (solid) and with (dashed) the Q-filter (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for j in analysis.joints:
        (line,) = ax.plot(analysis.frequency_hz, j.unfiltered, label=f"{j.joint}")
        if j.filtered is not None:
            ax.plot(analysis.frequency_hz, j.filtered, "--", color=line.get_color(),
                    label=f"{j.joint}, with Q")
    ax.axhline(1.0, color="k", lw=0.8)
    if analysis.qfilter is not None:
        ax.axvline(analysis.qfilter.cutoff_hz, color="grey", ls=":", lw=0.8, label="Q cut-off")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("trial-to-trial factor |F|")
    ax.set_title(f"{analysis.law} law, memory {analysis.memory.value}, "
                 f"delta {analysis.mass_uncertainty:g}, T = {analysis.period:g} s")
    ax.set_xscale("log")
    ax.set_xlim(analysis.frequency_hz[1], analysis.nyquist_hz)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def format_robustness(report: Robustness) -> str:
    """One line per delta checked, then the verdict (a WARNING when not robust)."""
    lines = [f"norm-optimal weights against norm_optimal.uncertainty_range "
             f"[{report.low:g}, {report.high:g}] (delta: max |F| over joints and frequencies; "
             "||F||_2 of the lifted map, plant linearised along the reference):"]
    deltas = report.deltas
    for i, (d, f) in enumerate(zip(deltas, report.frequency_worst, strict=True)):
        lifted = "" if not report.lifted else \
            (f", lifted ||F||_2 {report.lifted[i].norm:.6f} "
             f"(1 {report.lifted[i].norm - 1.0:+.1e})")
        lines.append(f"  delta {d:6.3f}: max |F| {f:.6f}{lifted}")
    if report.lifted_skipped:
        lines.append(f"  ({report.lifted_skipped})")
    if report.robust:
        lines.append("  robust: no factor above 1 in the range (learning is monotone in norm, "
                     "the unlearned directions stay as they are)")
    else:
        norms = [r.norm for r in report.lifted] or [0.0] * len(deltas)
        bad = [d for d, f, n in zip(deltas, report.frequency_worst, norms, strict=True)
               if f > 1.0 + ROBUST_TOLERANCE or n > 1.0 + ROBUST_TOLERANCE]
        lines.append("  WARNING: the weights are not robust to the configured uncertainty "
                     "range: a factor exceeds 1 at delta = " + ", ".join(f"{d:g}" for d in bad)
                     + " (raise norm_optimal.weight_input_change, or move "
                     "norm_optimal.model_mass_uncertainty towards that end)")
    return "\n".join(lines)


def format_growth(fit: GrowthFit | None, joint_names: Sequence[str],
                  at_limit: np.ndarray | None = None) -> str:
    """One line: per joint the fitted factor per trial and, if flagged, GROWING; a joint
    without enough data says so (never a NaN). A joint whose learned input is held at
    ``feedforward_limit`` (``at_limit``, :func:`growth.held_at_limit`) is AT ITS LIMIT: the
    verdict says so, never "bounded" (the limit holds it, not convergence)."""
    held = [name for name, flag in zip(joint_names, np.zeros(len(joint_names), bool)
                                       if at_limit is None else at_limit, strict=True) if flag]
    limit_note = ("" if not held else
                  f" -> AT ITS LIMIT on {', '.join(held)} (max |u_ff| = feedforward_limit: the "
                  "limit holds the learned input there, learning did not settle it)")
    if fit is None:
        return f"growth of max |u_ff|: too few trials (< {MIN_TRIALS}) to tell" + limit_note
    cells = []
    span = fit.last_trial - fit.first_trial + 1
    usable = fit.usable if fit.usable.size else np.full(len(joint_names), span)
    converging = fit.converging if fit.converging.size else np.zeros(len(joint_names), bool)
    for name, r, s, flag, n, settling in zip(joint_names, fit.rate, fit.stderr, fit.growing,
                                            usable, converging, strict=True):
        if n == 0:
            cells.append(f"{name} joint still (no learned input)")
        elif not np.isfinite(r):
            cells.append(f"{name} not enough data ({n} trial{'s' if n != 1 else ''} with a "
                         f"learned input, needs {MIN_TRIALS})")
        else:
            cells.append(f"{name} {100.0 * r:+.3f}+-{100.0 * s:.3f} %/trial"
                         + (" GROWING" if flag else " AT ITS LIMIT" if name in held else
                            " (approaching its limit)" if settling and r > 0 else ""))
    if fit.any_growing:
        verdict = " -> LEARNED INPUT KEEPS GROWING (the error may still look fine)" + (
            limit_note.replace(" -> ", "; ") if held else "")
    elif held:
        verdict = limit_note
    elif not np.any(np.isfinite(fit.rate)):
        verdict = " -> not enough data to tell"
    else:
        verdict = " -> bounded"
    return (f"growth of max |u_ff| over trials {fit.first_trial}-{fit.last_trial}: "
            + "; ".join(cells) + verdict)
