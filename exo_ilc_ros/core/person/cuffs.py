"""The cuffs' names and a trial's cuff metrics, light (numpy only: the run summary and a reader
of bags or JSON import it without MuJoCo or numba), and the key-values that carry the metrics
in a trial summary (``/ilc/trial_summary``, a bag, ``/ilc/trial_metrics``)."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Mapping, Sequence

import numpy as np

CUFFS = ("upper_arm", "forearm")
"""The cuffs, in the order of every per-cuff array."""
CUFF_METRICS = ("peak_force_N", "rms_force_N", "peak_torque_Nm", "rms_torque_Nm")
"""A trial's cuff metrics per cuff, in the order of :func:`cuff_metrics`' columns (the JSON's
``trials[].cuff_forces.<cuff>`` names and the summary's ``cuff/<cuff>/<name>`` keys)."""
CUFF_KEY_PREFIX = "cuff/"


def cuff_metrics(wrench: np.ndarray) -> np.ndarray:
    """Per cuff of a trial's (N+1, cuffs, 6) wrench log: [peak |F| (N), RMS |F| (N),
    peak |T| (N m), RMS |T| (N m)] over its finite samples, shape (cuffs, 4)."""
    finite = np.all(np.isfinite(wrench.reshape(wrench.shape[0], -1)), axis=1)
    w = wrench[finite]
    out = np.zeros((wrench.shape[1], 4))
    if not w.shape[0]:
        return out
    force = np.linalg.norm(w[:, :, :3], axis=2)
    torque = np.linalg.norm(w[:, :, 3:], axis=2)
    out[:, 0] = force.max(axis=0)
    out[:, 1] = np.sqrt(np.mean(force ** 2, axis=0))
    out[:, 2] = torque.max(axis=0)
    out[:, 3] = np.sqrt(np.mean(torque ** 2, axis=0))
    return out


def beyond_cuff_limit(wrench: np.ndarray, limit: Sequence[float]) -> int:
    """The first cuff whose |force| at one sample (``wrench``: (cuffs, 6)) is above its limit
    (``safety.cuff_force_limit``; 0: no limit), or -1: the one check of the cuff-force
    limit, in-process (:mod:`.experiment`) and in the graph (the plant node's hold, the
    supervisor's record)."""
    for c, most in enumerate(limit):
        if most > 0.0 and math.hypot(*wrench[c, :3]) > most:
            return c
    return -1


def first_beyond_cuff_limit(wrench: np.ndarray, limit: Sequence[float]) -> int:
    """The first sample of a trial's (N+1, cuffs, 6) wrench log at which a cuff presses past
    its limit (:func:`beyond_cuff_limit`), or -1."""
    for i in range(wrench.shape[0]):
        if beyond_cuff_limit(wrench[i], limit) >= 0:
            return i
    return -1


def cuff_key(cuff: str, metric: str) -> str:
    """The trial summary's key of one cuff metric: ``cuff/<cuff>/<metric>``."""
    return f"{CUFF_KEY_PREFIX}{cuff}/{metric}"


def cuff_summary_values(wrench: np.ndarray | None) -> list[tuple[str, str]]:
    """The trial summary's key-values of a trial's cuff wrench log (:func:`cuff_metrics`,
    floats as ``repr``: they parse back exactly); none without a person (``wrench`` None)."""
    if wrench is None:
        return []
    metrics = cuff_metrics(np.asarray(wrench, dtype=float))
    return [(cuff_key(cuff, name), repr(float(metrics[c, m])))
            for c, cuff in enumerate(CUFFS) for m, name in enumerate(CUFF_METRICS)]


def cuff_metrics_of_values(values: Mapping[str, str]) -> np.ndarray | None:
    """Inverse of :func:`cuff_summary_values`: the (cuffs, 4) metrics of a trial summary's
    key-values, or None if it has none (no person; a value that does not parse reads NaN)."""
    if cuff_key(CUFFS[0], CUFF_METRICS[0]) not in values:
        return None
    out = np.full((len(CUFFS), len(CUFF_METRICS)), np.nan)
    for c, cuff in enumerate(CUFFS):
        for m, name in enumerate(CUFF_METRICS):
            with contextlib.suppress(ValueError):  # a value that does not parse: NaN
                out[c, m] = float(values.get(cuff_key(cuff, name), "nan"))
    return out


def cuff_table(summaries: Sequence[Mapping[str, str]]) -> np.ndarray | None:
    """The (K, cuffs, 4) cuff metrics of K trial summaries' key-values, or None if none of
    them has any (no person); a trial without them reads NaN."""
    rows = [cuff_metrics_of_values(values) for values in summaries]
    if not rows or all(r is None for r in rows):
        return None
    empty = np.full((len(CUFFS), len(CUFF_METRICS)), np.nan)
    return np.array([empty if r is None else r for r in rows])
