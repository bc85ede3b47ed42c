"""The cuffs' names and a trial's cuff metrics, light (numpy only: the run summary and a reader
of bags or JSON import it without MuJoCo or numba)."""

from __future__ import annotations

import numpy as np

CUFFS = ("upper_arm", "forearm")
"""The cuffs, in the order of every per-cuff array."""


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
