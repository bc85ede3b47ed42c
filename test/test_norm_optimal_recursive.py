"""Norm-optimal ILC without lifted matrices (core/learning/norm_optimal_recursive.py) against the
lifted form of core/learning/norm_optimal_model.py, its oracle: the Riccati update (R3)-(R5) equals
L e + Phi u of (NO2), the banded QP equals the lifted form's QP (NO3), on 3 and 7 joints."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core.learning import norm_optimal, norm_optimal_model, norm_optimal_qp
from exo_ilc_ros.core.learning.factory import build_law
from exo_ilc_ros.core.learning.norm_optimal_recursive import lifted_gradient, riccati_gains
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.sim.experiment import Experiment

SHORT = {"trajectory.duration": 0.6, "law": "norm_optimal"}


def _config(**overrides: Any) -> Config:
    return load_config(overrides={**SHORT, **overrides})


def _seven_joints(**overrides: Any) -> Config:
    """A 7-joint cone arm: every per-joint list of the shipped config widened to 7."""
    base = _config()
    n = 7
    wide: dict[str, Any] = {p.name: [base[p.name][i % 3] for i in range(n)]
                            for p in schema.PARAMETERS if p.per_joint}
    wide.update({"joint_names": [f"joint_{i + 1}" for i in range(n)],
                 "model.link_masses": [1.2, 1.4, 1.1, 0.9, 0.8, 0.6, 0.4],
                 "model.link_lengths": [0.1, 0.3, 0.25, 0.1, 0.2, 0.1, 0.08],
                 "model.radius_proximal": [0.05] * n, "model.radius_distal": [0.04] * n,
                 "model.joint_axes": ["y", "x", "y", "z", "y", "x", "y"]})
    return _config(**{**wide, **overrides})


def _random_trial(config: Config, seed: int) -> tuple[np.ndarray, np.ndarray]:
    model = norm_optimal_model.lifted_model(config)
    rng = np.random.default_rng(seed)
    shape = (model.samples, model.joints)
    return 0.5 * rng.standard_normal(shape), 0.01 * rng.standard_normal(shape)


CASES = [
    ("linearised, no input-size weight", {}),
    ("linearised, input-size weight", {"norm_optimal.weight_input_size": [1e-6, 0.0, 2e-6],
                                       "norm_optimal.weight_error": [1.0, 2.0, 0.5]}),
    ("per-joint model", {"norm_optimal.model_kind": "per_joint"}),
    ("heavier input-change weight", {"norm_optimal.weight_input_change": [1e-4, 1e-5, 1e-6],
                                     "norm_optimal.model_mass_uncertainty": 0.12}),
    ("1 kHz", {"control.period": 0.001, "integration_step": 0.001,
               "trajectory.duration": 0.3}),
]


@pytest.mark.parametrize(("label", "overrides"), CASES, ids=[c[0] for c in CASES])
def test_riccati_update_is_the_lifted_update(label: str, overrides: dict[str, Any]) -> None:
    """(R3)-(R5) give Phi u + L e of (NO2) to 1e-9 of the change (3 joints, 61 samples at
    100 Hz, 301 at 1 kHz)."""
    config = _config(**overrides)
    dense = norm_optimal_model.learning_matrices(config)
    ours = norm_optimal_model.recursive_matrices(config)
    u, e = _random_trial(config, 1)
    expected = dense.next_feedforward(u.ravel(), e.ravel())
    got = ours.next_feedforward(u.ravel(), e.ravel())
    scale = np.max(np.abs(expected - u.ravel()))
    assert scale > 1e-3
    assert np.max(np.abs(got - expected)) <= 1e-9 * scale
    # the 2-D shape gives the same numbers
    np.testing.assert_array_equal(ours.next_feedforward(u, e).ravel(), got)


def test_seven_joints() -> None:
    """The same on a 7-joint arm (coupled, time-varying linearised model), with an input-size
    weight on some joints."""
    config = _seven_joints(**{"norm_optimal.weight_input_size": [0.0, 1e-6, 0.0, 0.0, 3e-6,
                                                                 0.0, 1e-7]})
    dense = norm_optimal_model.learning_matrices(config)
    ours = norm_optimal_model.recursive_matrices(config)
    assert ours.gains.joints == 7
    u, e = _random_trial(config, 2)
    expected = dense.next_feedforward(u.ravel(), e.ravel())
    got = ours.next_feedforward(u.ravel(), e.ravel())
    scale = np.max(np.abs(expected - u.ravel()))
    assert np.max(np.abs(got - expected)) <= 1e-9 * scale


def test_adjoint_sweep_is_g_transpose() -> None:
    """The co-state sweep with K = 0 is G^T We e (the model's A, B reproduce G)."""
    config = _config(**{"norm_optimal.weight_error": [1.0, 2.0, 0.5]})
    model = norm_optimal_model.lifted_model(config)
    w = norm_optimal_model.Weights.of(config)
    gains = riccati_gains(model.a, model.b, model.k, w.error, w.input_change, w.input_size)
    _, e = _random_trial(config, 3)
    expected = model.g.T @ (np.tile(w.error, model.samples) * e.ravel())
    got = lifted_gradient(gains, e).ravel()
    assert np.max(np.abs(got - expected)) <= 1e-12 * np.max(np.abs(expected))


def test_no_error_no_input_size_weight_no_change() -> None:
    config = _config()
    ours = norm_optimal_model.recursive_matrices(config)
    u, _ = _random_trial(config, 4)
    np.testing.assert_array_equal(ours.gains.change(u, np.zeros_like(u)), 0.0)
    # with an input-size weight, e = 0 leaks u towards 0 exactly as Phi does
    leaky = _config(**{"norm_optimal.weight_input_size": [1e-6, 1e-6, 1e-6]})
    dense = norm_optimal_model.learning_matrices(leaky)
    got = norm_optimal_model.recursive_matrices(leaky).next_feedforward(u.ravel(), np.zeros(u.size))
    expected = dense.phi @ u.ravel()
    assert np.max(np.abs(got - expected)) <= 1e-9 * np.max(np.abs(expected - u.ravel()))


def test_memory_is_linear_in_the_samples() -> None:
    """The gains hold a few small matrices per sample, nothing (samples)^2."""
    short = norm_optimal_model.recursive_matrices(_config(**{"trajectory.duration": 0.5}))
    long = norm_optimal_model.recursive_matrices(_config(**{"trajectory.duration": 2.0}))
    per_sample = long.gains.nbytes / long.gains.samples
    assert per_sample == pytest.approx(short.gains.nbytes / short.gains.samples, rel=0.02)
    assert per_sample < 8 * (2 * 3) ** 2 * 4  # B, K, M^-1, F: < four 6x6 matrices of doubles


def test_zero_stage_weight_is_refused() -> None:
    model = norm_optimal_model.lifted_model(_config())
    with pytest.raises(ValueError, match="must be > 0 for every joint"):
        riccati_gains(model.a, model.b, model.k, np.ones(3), np.array([1e-8, 0.0, 1e-8]),
                      np.zeros(3))


def test_the_law_uses_the_recursive_form() -> None:
    """NormOptimalLaw's update, measured trial in, equals the lifted (NO2) update."""
    config = _config(**{"norm_optimal.weight_input_size": [1e-6, 0.0, 2e-6]})
    law = build_law(config)
    assert isinstance(law, norm_optimal.NormOptimalLaw)
    assert isinstance(law.matrices, norm_optimal_model.RecursiveMatrices)
    record = Experiment(config.with_mass_uncertainty(0.15)).run_trial(
        0.1 * np.random.default_rng(5).standard_normal((61, 3)), 1)
    dense = norm_optimal_model.learning_matrices(config)
    expected = dense.next_feedforward(record.feedforward.ravel(), record.error.ravel())
    got = law.update(record).feedforward.ravel()
    scale = np.max(np.abs(expected - record.feedforward.ravel()))
    assert np.max(np.abs(got - expected)) <= 1e-9 * scale


def _constrained_case(config: Config, tight: bool, feedforward_bound: float = 0.3
                      ) -> tuple[Any, Any, Any]:
    config = config.replace({"norm_optimal.constrained": True})
    record = Experiment(config.with_mass_uncertainty(0.15)).run_trial(
        np.zeros((config_samples(config), config.joints)), 1)
    if tight:
        need = np.max(np.abs(record.effort), axis=0)
        config = config.replace({"control.effort_limit": [float(x) for x in 0.98 * need],
                                 "feedforward_limit": [feedforward_bound] * config.joints,
                                 "norm_optimal.effort_margin": 0.0})
    law = norm_optimal.NormOptimalLaw.from_config(config)
    assert law.constraints is not None
    return law, record, norm_optimal_model.learning_matrices(config)


def config_samples(config: Config) -> int:
    return norm_optimal_model.lifted_model(config).samples


@pytest.mark.parametrize("tight", [False, True], ids=["loose", "tight"])
def test_banded_qp_is_the_lifted_qp(tight: bool) -> None:
    """The banded QP (NO3) equals norm_optimal_qp.solve_constrained to 1e-9 of the change, with
    and without active constraints; loose, it is the unconstrained Riccati update."""
    law, record, dense = _constrained_case(_config(), tight)
    expected = norm_optimal_qp.solve_constrained(dense, law.constraints, record)
    got = norm_optimal_qp.solve_constrained_recursive(law.matrices, law.constraints, record)
    scale = np.max(np.abs(expected.change))
    assert np.max(np.abs(got.change - expected.change)) <= 1e-9 * scale
    np.testing.assert_allclose(got.predicted_effort, expected.predicted_effort, rtol=0,
                               atol=1e-9 * np.max(np.abs(expected.predicted_effort)))
    np.testing.assert_array_equal(got.effort_active, expected.effort_active)
    np.testing.assert_array_equal(got.feedforward_active, expected.feedforward_active)
    if tight:
        assert np.any(got.effort_active) and np.any(got.feedforward_active)
        assert law.update(record).notes == norm_optimal_qp.constraint_notes(got)
    else:
        assert not np.any(got.effort_active) and not np.any(got.feedforward_active)
        free = law.matrices.gains.change(record.feedforward, record.error)
        assert np.max(np.abs(got.change - free)) <= 1e-6 * scale  # Clarabel's tolerance


def test_banded_qp_seven_joints() -> None:
    """The banded QP on the 7-joint arm, constraints active, equals the lifted form's QP."""
    law, record, dense = _constrained_case(_seven_joints(**{"trajectory.duration": 0.4}), True,
                                           feedforward_bound=0.0)
    expected = norm_optimal_qp.solve_constrained(dense, law.constraints, record)
    got = norm_optimal_qp.solve_constrained_recursive(law.matrices, law.constraints, record)
    assert np.any(got.effort_active)
    scale = np.max(np.abs(expected.change))
    assert np.max(np.abs(got.change - expected.change)) <= 1e-9 * scale
