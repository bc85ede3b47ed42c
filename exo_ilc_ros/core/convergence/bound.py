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


def iterations_to_bound(max_abs_errors: np.ndarray, bound: float) -> IterationsToBound:
    """First and settled trial (1-based) per joint from the (K, joints) max |e| table."""
    within = np.asarray(max_abs_errors) <= bound
    first: list[int | None] = []
    settled: list[int | None] = []
    for j in range(within.shape[1]):
        hits = np.flatnonzero(within[:, j])
        first.append(int(hits[0]) + 1 if hits.size else None)
        misses = np.flatnonzero(~within[:, j])
        if not within[-1, j]:
            settled.append(None)
        else:
            settled.append(int(misses[-1]) + 2 if misses.size else 1)
    return IterationsToBound(first, settled)
