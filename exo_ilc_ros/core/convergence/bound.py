"""Iterations to the error bound: the paper's measure of how fast a law learns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class IterationsToBound:
    """Per joint: the first trial within the bound, and the trial from which it stays within
    (None where never reached, or not yet staying within at the last trial)."""

    first: list[int | None]
    settled: list[int | None]


def iterations_to_bound(max_abs_errors: np.ndarray, bound: float,
                        known: np.ndarray | None = None) -> IterationsToBound:
    """First and settled trial (1-based) per joint from the (K, joints) max |e| table (a NaN
    row: a trial that diverged, out of the bound). ``known`` (K booleans; None: all) leaves
    out the trials whose max |e| is not known (a bag's trial left out as damaged): they are
    neither within nor out of the bound, so "settled" is the first known trial after the last
    known one out of it."""
    within = np.asarray(max_abs_errors) <= bound
    rows = np.arange(within.shape[0]) if known is None else np.flatnonzero(known)
    first: list[int | None] = []
    settled: list[int | None] = []
    for j in range(within.shape[1]):
        inside = within[rows, j]
        hits = rows[inside]
        first.append(int(hits[0]) + 1 if hits.size else None)
        misses = rows[~inside]
        if not rows.size or not inside[-1]:
            settled.append(None)
        elif misses.size:
            settled.append(int(rows[np.searchsorted(rows, misses[-1]) + 1]) + 1)
        else:
            settled.append(int(rows[0]) + 1)
    return IterationsToBound(first, settled)
