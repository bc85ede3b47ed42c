"""Issue 33, identifiability: a pair of parameters the movement cannot separate is named.

Hand-constructed regressors (no simulation): a friction column tanh(v / v_s) and a constant
offset column. On a movement that never reverses, tanh(v / v_s) is nearly constant, so the two
columns are nearly collinear and their estimates correlate by nearly -1; on a movement that
reverses, tanh(v / v_s) has mean about zero and is nearly orthogonal to the constant."""

from __future__ import annotations

import numpy as np

from exo_ilc_ros.core.learning.identification import inseparable_pairs

STRIBECK = 0.01
NAMES = ("damping", "coulomb_friction", "offset")


def _covariance_scaled(velocity: np.ndarray) -> np.ndarray:
    """(Phi_s^T Phi_s)^-1 with unit-norm columns [v, tanh(v / v_s), 1]."""
    phi = np.column_stack([velocity, np.tanh(velocity / STRIBECK), np.ones_like(velocity)])
    phi = phi / np.linalg.norm(phi, axis=0)
    return np.asarray(np.linalg.inv(phi.T @ phi))


def test_friction_and_offset_inseparable_when_the_movement_never_reverses() -> None:
    t = np.linspace(0.0, 4.0, 2001)
    velocity = 0.3 + 0.2 * np.sin(2.0 * np.pi * t / 4.0)  # always > 0.1 rad/s: never reverses
    pairs = inseparable_pairs(_covariance_scaled(velocity), NAMES)
    assert [(a, b) for a, b, _ in pairs] == [("coulomb_friction", "offset")]
    # tanh(v / v_s) >= tanh(10) here: the columns are the same to 1e-8, correlation -> -1
    assert pairs[0][2] < -0.999999


def test_friction_and_offset_separable_when_the_movement_reverses() -> None:
    t = np.linspace(0.0, 4.0, 2001)
    velocity = 0.3 * np.sin(2.0 * np.pi * t / 4.0)  # there and back
    cov = _covariance_scaled(velocity)
    assert inseparable_pairs(cov, NAMES) == ()
    # hand check: sin and tanh(sin / v_s) are odd about the midpoint, the constant even, so the
    # friction-offset correlation is about zero; the velocity-friction one is large but < 0.99
    d = np.sqrt(np.diag(cov))
    assert abs(cov[1, 2] / (d[1] * d[2])) < 0.05


def test_unexcited_parameter_is_in_no_pair() -> None:
    cov = np.array([[1.0, 0.0, 0.0], [0.0, np.inf, np.nan], [0.0, np.nan, 1.0]])
    assert inseparable_pairs(cov, NAMES) == ()
