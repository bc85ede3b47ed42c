"""Test oracle: the plain trial kernel (no error envelope, no second clamp), against which the
package's guarded trial (:func:`exo_ilc_ros.core.loop.trial.simulate_trial_guarded`) must give
the same doubles while every |e_j| stays within the envelope."""

from __future__ import annotations

import numpy as np
from numba import njit

from exo_ilc_ros.core.arm.dynamics import workspace
from exo_ilc_ros.core.loop.controller import ComputedTorque, Setpoint, control_into
from exo_ilc_ros.core.loop.plant import PlantIntegration, rk4_period


@njit(cache=True, error_model="numpy")
def simulate_trial(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, kp: np.ndarray,
                   kd: np.ndarray, effort_limit: np.ndarray, period: float, substeps: int,
                   plant: tuple, nominal: tuple, mode: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The trial of ``simulate_trial_guarded`` without the error envelope and without the
    plant's second clamp. Returns sampled q, qdot, u and effort."""
    n_samples, n = u_ff.shape
    q_log = np.empty((n_samples, n))
    qd_log = np.empty((n_samples, n))
    u_log = np.empty((n_samples, n))
    effort_log = np.empty((n_samples, n))
    torque = ComputedTorque(nominal, effort_limit, workspace(n))
    integration = PlantIntegration(period, substeps, plant, nominal, mode, workspace(n),
                                   np.empty((10, n)), np.empty(2 * n))
    q = q_ref[0].copy()
    qd = qd_ref[0].copy()
    zero = np.zeros(n)
    for i in range(n_samples):
        q_log[i] = q
        qd_log[i] = qd
        control_into(Setpoint(u_ff[i], q_ref[i], qd_ref[i]), q, qd, zero, kp, kd, torque,
                     u_log[i], effort_log[i])
        if i + 1 < n_samples:
            rk4_period(q, qd, effort_log[i], integration)
    return q_log, qd_log, u_log, effort_log
