"""Therapy metrics as a terminal table (``exo-ilc simulate --patient``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..core.programs.metrics import METRIC_UNITS, TrialMetrics

ROWS = (("max_error", "peak true |e|"), ("rms_error", "RMS true e"),
        ("assistance_rms", "assistance (RMS beyond gravity comp.)"),
        ("feedforward_rms", "learned feed-forward RMS"),
        ("patient_share", "patient's share of the work"),
        ("spasticity", "velocity-dependent resistance B"))
"""Per-joint metrics in the table: attribute and label."""


def _cells(values: np.ndarray) -> str:
    return " ".join(f"{x:>10.3g}" for x in values)


def format_metrics(metrics: Sequence[TrialMetrics], joint_names: Sequence[str],
                   title: str) -> str:
    """First and last trial of each metric per joint, with units."""
    if not metrics:
        return f"{title}: no trials"
    first, last = metrics[0], metrics[-1]
    width = max(len(label) + len(METRIC_UNITS[name]) + 3 for name, label in ROWS)
    head = f"{'':<{width}} {'':>6} " + " ".join(f"{n[:10]:>10}" for n in joint_names)
    lines = [title, head, "-" * len(head)]
    for name, label in ROWS:
        text = f"{label} ({METRIC_UNITS[name]})"
        for which, m in (("trial " + str(first.trial), first), ("trial " + str(last.trial), last)):
            lines.append(f"{text:<{width}} {which:>6} {_cells(getattr(m, name))}")
            text = ""
    lines.append(f"{'patient share, whole arm (1)':<{width}} first {first.patient_share_total:.3f}"
                 f", last {last.patient_share_total:.3f}")
    lines.append(f"{'smoothness, SPARC of |qdot| (1)':<{width}} first {first.smoothness:.3f}, "
                 f"last {last.smoothness:.3f} (closer to 0: smoother)")
    aborted = [m.trial for m in metrics if m.aborted]
    lines.append(f"aborted by the error envelope: {aborted or 'none'}")
    return "\n".join(lines)


def format_session_metrics(done: Any, joint_names: Sequence[str]) -> str:
    """The table of one exercise of a session (:class:`..core.therapy.ExerciseResult`)."""
    start = "from zero" if done.started_from is None else f"from v{done.started_from}"
    title = (f"Therapy metrics: patient {done.patient}, exercise {done.exercise}, "
             f"{len(done.metrics)} trials {start}, saved as profile v{done.version}")
    return format_metrics(done.metrics, joint_names, title)
