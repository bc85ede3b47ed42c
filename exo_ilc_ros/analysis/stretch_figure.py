"""The stretch test's figure: reflex stiffness and threshold angle against stretch velocity, one
line per MAS grade (``exo-ilc stretch-test --plot``)."""

from __future__ import annotations

from collections.abc import Sequence

from matplotlib.figure import Figure

from ..core.person.stretch_test import StretchMeasure


def stretch_figure(measures: Sequence[StretchMeasure]) -> Figure:
    """Two panels: reflex stiffness (N m/rad) and reflex threshold angle (deg flexion) per
    velocity (deg/s), a line per grade (a grade without reflex draws no threshold)."""
    fig = Figure(figsize=(9.0, 3.6))
    stiffness, threshold = fig.subplots(1, 2)
    grades = list(dict.fromkeys(m.grade for m in measures))
    for grade in grades:
        rows = [m for m in measures if m.grade == grade]
        stiffness.plot([m.velocity for m in rows], [m.stiffness for m in rows], marker="o",
                       label=f"MAS {grade}")
        with_reflex = [m for m in rows if m.threshold_angle is not None]
        threshold.plot([m.velocity for m in with_reflex],
                       [m.threshold_angle for m in with_reflex], marker="o",
                       label=f"MAS {grade}")
    stiffness.set_xlabel("stretch velocity (deg/s)")
    stiffness.set_ylabel("reflex stiffness (N m/rad)")
    threshold.set_xlabel("stretch velocity (deg/s)")
    threshold.set_ylabel("reflex threshold angle (deg flexion)")
    for axes in (stiffness, threshold):
        axes.grid(True, linewidth=0.3)
        axes.legend(fontsize=7)
    fig.suptitle("Stretch test: ramp-and-hold elbow extension (McPherson et al. 2018's "
                 "protocol)", fontsize=9)
    fig.tight_layout()
    return fig
