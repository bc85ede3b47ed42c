"""The robustness study at a glance: the settled floor per law (rows) and scenario (columns),
one panel per mass uncertainty; colour from far below the bound (green) to far above (red),
growing learned inputs hatched, envelope aborts and failed runs marked in the cell."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from ..core.programs.study_rows import FLOOR_WINDOW, StudyRow

DECADES_BELOW = 3.0
DECADES_ABOVE = 2.0
"""The colour scale spans bound / 10^3 (green) .. the bound (yellow) .. bound * 10^2 (red)."""


def _ordered(values: Sequence[str]) -> list[str]:
    seen: list[str] = []
    for v in values:
        if v not in seen:
            seen.append(v)
    return seen


def _short(x: float) -> str:
    """``4.5e-5``, ``1.04``: a floor in few characters."""
    if x >= 0.1:
        return f"{x:.2f}"
    mantissa, _, exponent = f"{x:.1e}".partition("e")
    return f"{mantissa}e{int(exponent)}"


def study_figure(rows: Sequence[StudyRow]) -> Figure:
    """Heatmaps of the settled floor (module docstring); ``rows`` as :func:`study_rows` gives
    them."""
    laws = _ordered([r.law for r in rows])
    scenarios = _ordered([r.scenario for r in rows])
    deltas = sorted({r.mass_uncertainty for r in rows})
    by_key = {(r.law, r.scenario, r.mass_uncertainty): r for r in rows}
    bound = rows[0].error_bound if rows else 0.005
    panels = max(len(deltas), 1)
    width = 1.1 + panels * (0.95 * len(scenarios) + 0.4)
    height = 1.9 + 0.5 * len(laws)
    fig = Figure(figsize=(max(width, 6.0), height), layout="constrained")
    axes = fig.subplots(1, panels, sharey=True, squeeze=False)[0]
    cmap = colormaps["RdYlGn_r"].with_extremes(bad="0.75")
    norm = TwoSlopeNorm(0.0, -DECADES_BELOW, DECADES_ABOVE)
    image = None
    for ax, delta in zip(axes, deltas, strict=False):
        grid = np.full((len(laws), len(scenarios)), np.nan)
        for i, law in enumerate(laws):
            for j, scenario in enumerate(scenarios):
                row = by_key.get((law, scenario, delta))
                if row is not None and row.finite and np.isfinite(row.floor) and row.floor > 0:
                    grid[i, j] = math.log10(row.floor / bound)
        image = ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, norm=norm, aspect="auto")
        for i, law in enumerate(laws):
            for j, scenario in enumerate(scenarios):
                row = by_key.get((law, scenario, delta))
                if row is None:
                    continue
                lines = []
                if not row.finite:
                    lines.append("failed")
                elif np.isfinite(row.floor):
                    lines.append(_short(row.floor))
                marks = []
                if row.growing_seeds:
                    marks.append("growing")
                    ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///",
                                           edgecolor="0.15", linewidth=0))
                if row.late_aborts:
                    marks.append(f"{row.late_aborts} abort" + ("s" if row.late_aborts > 1
                                                               else ""))
                if marks:
                    lines.append(", ".join(marks))
                ax.text(j, i, "\n".join(lines), ha="center", va="center", fontsize=7,
                        color="black", bbox={"boxstyle": "round,pad=0.15", "facecolor": "white",
                                             "alpha": 0.6, "linewidth": 0})
        ax.set_xticks(range(len(scenarios)), scenarios, rotation=35, ha="right", fontsize=8)
        ax.set_yticks(range(len(laws)), laws, fontsize=8)
        ax.set_title(f"{100 * delta:g} % mass uncertainty", fontsize=9)
        ax.tick_params(length=0)
    if image is not None:
        bar = fig.colorbar(image, ax=list(axes), shrink=0.9, pad=0.01)
        ticks = np.arange(-DECADES_BELOW, DECADES_ABOVE + 1)
        bar.set_ticks(list(ticks), labels=[f"{bound * 10 ** t:g}" for t in ticks], fontsize=7)
        bar.set_label("settled floor (rad); bound in the middle", fontsize=8)
    window = min(FLOOR_WINDOW, rows[0].trials) if rows else FLOOR_WINDOW
    seeds = f", median over {rows[0].seeds} seeds" if rows and rows[0].seeds > 1 else ""
    title = (f"Which law survives which patient: median true max |e| over the last "
             f"{window} of {rows[0].trials if rows else 0} trials, worst joint{seeds}\n"
             "hatched: learned input still growing; grey: run failed")
    fig.suptitle(fit_title(title, fig.get_figwidth(), TITLE_SIZE), fontsize=TITLE_SIZE)
    return fig


TITLE_SIZE = 9


def fit_title(text: str, width_inches: float, fontsize: float) -> str:
    """``text`` wrapped at word boundaries to lines that fit ``width_inches`` at ``fontsize``
    (a sans-serif character is at most about 0.6 em wide on average), so no title is clipped
    by a narrow figure."""
    per_line = max(20, int(width_inches * 72.0 / (0.6 * fontsize)))
    return "\n".join(textwrap.fill(line, per_line) for line in text.splitlines())
