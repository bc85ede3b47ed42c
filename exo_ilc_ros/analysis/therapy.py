"""Therapy metrics as a therapist reads them: angles in degrees, shares in per cent, an
indicator the trial cannot measure shown as "not measurable" with the reason (the data files
keep SI units, rad; core/programs/metrics.py). The terminal table of ``exo-ilc simulate/run
--patient`` and the session report's cells both come from here."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..core.programs.metrics import TrialMetrics

DEGREES = 180.0 / math.pi
DISPLAY = {
    "max_error": ("peak true |e|", "deg", DEGREES),
    "rms_error": ("RMS true error", "deg", DEGREES),
    "assistance_rms": ("assistance (RMS torque beyond gravity compensation)", "N m", 1.0),
    "feedforward_rms": ("learned feed-forward (RMS)", "deg/s^2", DEGREES),
    "patient_share": ("patient's share of the work", "%", 100.0),
    "spasticity": ("velocity-dependent resistance B (spasticity indicator)", "N m s/deg",
                   1.0 / DEGREES),
}
"""Per-joint metric -> (label, unit shown, factor from the data's SI unit)."""
NOT_MEASURABLE = "not measurable"


def display_value(name: str, value: float) -> str:
    """One value of metric ``name`` in the unit a therapist reads (no unit text)."""
    if not np.isfinite(value):
        return NOT_MEASURABLE
    x = value * DISPLAY[name][2]
    return "0" if x == 0.0 else f"{x:.3g}"


def share_note(metrics: Sequence[TrialMetrics]) -> str:
    """What a share of 0 % means here (its resolution), or "" if none was recorded."""
    worst = max((m.patient_share_total_resolution for m in metrics), default=0.0)
    if worst <= 0.0:
        return ""
    return (f"patient's share: 0 % means within the measurement's resolution (at most "
            f"+-{100.0 * worst:.2g} % here: the robot's torque is held over each control "
            "period; core/programs/metrics.py); a passive patient's share is 0 %")


def reasons(metrics: Sequence[TrialMetrics], joint_names: Sequence[str]) -> list[str]:
    """One line per joint whose spasticity indicator is not measurable, with the reason."""
    out = []
    for m in metrics:
        for name, why in zip(joint_names, m.spasticity_reasons(), strict=True):
            line = f"trial {m.trial}: B on {name} not measurable: {why}"
            if why and line not in out:
                out.append(line)
    return out


def format_metrics(metrics: Sequence[TrialMetrics], joint_names: Sequence[str],
                   title: str) -> str:
    """First and last trial of each metric per joint, with units a therapist reads."""
    if not metrics:
        return f"{title}: no trials"
    first, last = metrics[0], metrics[-1]
    width = max(len(label) + len(unit) + 3 for label, unit, _ in DISPLAY.values())
    cell = max([14] + [len(n) + 1 for n in joint_names])
    head = f"{'':<{width}} {'':>9} " + "".join(f"{n:>{cell}}" for n in joint_names)
    lines = [title, head, "-" * len(head)]
    for name, (label, unit, _) in DISPLAY.items():
        text = f"{label} ({unit})"
        for which, m in ((f"trial {first.trial}", first), (f"trial {last.trial}", last)):
            cells = "".join(f"{display_value(name, x):>{cell}}" for x in getattr(m, name))
            lines.append(f"{text:<{width}} {which:>9} {cells}")
            text = ""
    lines.append(f"{'patient share, whole arm (%)':<{width}} first "
                 f"{100.0 * first.patient_share_total:.3g}, last "
                 f"{100.0 * last.patient_share_total:.3g}")
    lines.append(f"{'smoothness, SPARC of |qdot| (1)':<{width}} first {first.smoothness:.3f}, "
                 f"last {last.smoothness:.3f} (closer to 0: smoother)")
    aborted = [m.trial for m in metrics if m.aborted]
    lines.append(f"aborted by the error envelope: {aborted or 'none'}")
    lines += reasons([first, last], joint_names)
    note = share_note([first, last])
    if note:
        lines.append(note)
    return "\n".join(lines)


def format_session_metrics(done: Any, joint_names: Sequence[str]) -> str:
    """The table of one exercise of a session (:class:`..core.therapy.ExerciseResult`)."""
    start = "from zero" if done.started_from is None else f"from v{done.started_from}"
    count = len(done.metrics)
    title = (f"Therapy metrics: patient {done.patient}, exercise {done.exercise}, "
             f"{count} trial{'s' if count != 1 else ''} {start}, saved as profile "
             f"v{done.version}")
    return format_metrics(done.metrics, joint_names, title)


def format_filed_metrics(therapy: dict[str, Any], joint_names: Sequence[str]) -> str:
    """The same table from a graph run's summary (``extra["therapy"]`` of ``exo-ilc run
    --patient``: the metrics of the trials its store holds)."""
    metrics = [TrialMetrics.from_json(m) for m in therapy.get("metrics", [])]
    start = therapy.get("profile_started_from")
    count = len(metrics)
    title = (f"Therapy metrics: patient {therapy.get('patient')}, exercise "
             f"{therapy.get('exercise')}, {count} trial{'s' if count != 1 else ''} "
             f"{'from zero' if start is None else f'from v{start}'}, saved as profile "
             f"v{therapy.get('profile_version')}")
    return format_metrics(metrics, joint_names, title)
