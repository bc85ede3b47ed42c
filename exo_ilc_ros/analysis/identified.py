"""The identified patient as text: the per-trial table of ``exo-ilc analyze`` and ``exo-ilc
simulate`` and the per-session trend of the therapy report (:mod:`..core.programs.identified`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["format_final", "format_table", "format_value", "trend"]

from ..core.programs.identified import SHOWN, SYMBOLS, UNITS, WORDS, Identified, format_value


def format_table(rows: Sequence[Identified], names: Sequence[str]) -> str:
    """Per joint one line per trial: B, F_c, K, q0, G (each with its 95 % interval), trusted,
    used in the loop (the table of ``exo-ilc analyze`` and ``exo-ilc simulate``)."""
    if not rows:
        return ""
    lines = []
    head = ["trial"] + [f"{SYMBOLS[p]} ({UNITS[p]})" for p in SHOWN] + ["trusted", "in loop"]
    for j, name in enumerate(names):
        table = [head]
        for row in rows:
            joint = row.joints[j]
            table.append([str(row.trial)] + [format_value(p, joint[p]) for p in SHOWN]
                         + ["yes" if joint.trustworthy else "no",
                            "yes" if joint.used else "no"])
        widths = [max(len(r[c]) for r in table) for c in range(len(head))]
        lines.append(f"identified {name} (95 % intervals; n.i.: not identifiable):")
        lines += ["  " + "  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True))
                  for r in table]
        last = rows[-1].joints[j]
        if last.reason:
            lines.append(f"  trial {rows[-1].trial}: {last.reason}")
        if last.inseparable:
            lines.append(f"  not separately identifiable (only the combination is used): "
                         f"{last.inseparable}")
    rejected = [f"trial {r.trial}: {r.rejected}" for r in rows if r.rejected]
    lines += [f"identification refused {item}" for item in rejected]
    return "\n".join(lines)


def trend(values: Sequence[tuple[str, float]], p: str, joint: str) -> str:
    """``elbow_flexion damping 0.82 -> 0.61 N m s/rad over 6 sessions`` from (session,
    estimate) in order (non-finite estimates left out; "" with fewer than two)."""
    known = [(s, v) for s, v in values if math.isfinite(v)]
    if len(known) < 2:
        return ""
    return (f"{joint} {WORDS[p]} {known[0][1]:.3g} -> {known[-1][1]:.3g} {UNITS[p]} over "
            f"{len(known)} sessions")


def format_final(identified: Identified, title: str) -> str:
    """The identification after the last trial, one line per joint with every parameter's
    95 % interval and unit (what ``exo-ilc simulate`` prints at the end of a run)."""
    lines = [f"{title}: the identified patient after trial {identified.trial} "
             "(95 % intervals; n.i.: not identifiable)"]
    for joint in identified.joints:
        cells = ", ".join(f"{SYMBOLS[p]} {format_value(p, joint[p])} {UNITS[p]}" for p in SHOWN)
        lines.append(f"  {joint.name}: {cells}; trusted {'yes' if joint.trustworthy else 'no'}"
                     f", in the loop {'yes' if joint.used else 'no'}")
        if joint.reason:
            lines.append(f"    {joint.reason}")
        if joint.inseparable:
            lines.append(f"    not separately identifiable (only the combination is used): "
                         f"{joint.inseparable}")
    if identified.rejected:
        lines.append(f"  trial {identified.trial}'s data refused: {identified.rejected}")
    return "\n".join(lines)
