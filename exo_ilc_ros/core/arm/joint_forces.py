"""The passive joint forces of eq (6) (its Q^v, Q^c, Q^f, which the paper sets to zero): viscous
friction, Coulomb friction and joint stiffness, evaluated at a state.

They live below both the plant (:func:`plant.rk4_period_with_joint_forces` evaluates them at
every RK4 stage) and the virtual patient (:mod:`.patient` fills the ``joint`` array), so the two
share one integrator. ``joint`` is the patient's per-joint parameter array; its first rows are
the ones below (:mod:`.patient` lists the rest).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)

VISCOUS = 0  # B: viscous friction + spastic damping (N m s/rad)
COULOMB = 1  # F_c (N m)
STIFFNESS = 2  # K: passive + spastic stiffness (N m/rad)
REST = 3  # q_0 (rad)


@njit(cache=True, error_model="numpy", inline="always")
def passive_effort_into(q: np.ndarray, qd: np.ndarray, effort: np.ndarray, joint: np.ndarray,
                        inverse_stribeck: float, out: np.ndarray) -> None:
    """``effort`` plus the passive joint forces of eq (6)'s Q^v, Q^f, Q^c:
    Q - B qdot - F_c tanh(qdot / v_s) - K (q - q_0), into ``out``."""
    for j in range(q.shape[0]):
        out[j] = (effort[j] - joint[VISCOUS, j] * qd[j]
                  - joint[COULOMB, j] * np.tanh(qd[j] * inverse_stribeck)
                  - joint[STIFFNESS, j] * (q[j] - joint[REST, j]))
