"""Assist-as-needed (core/learning/assist.py) against hand-computed cases, with the Q-filter, and in
analyze-loop's factor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from exo_ilc_ros.core import LinearLaw, Memory, SampledReference, TrialRecord, load_config
from exo_ilc_ros.core.convergence.factors import JointLoop, analyze_loop
from exo_ilc_ros.core.learning.assist import AssistAsNeededLaw, deadband_gate
from exo_ilc_ros.core.learning.factory import build_law
from exo_ilc_ros.core.learning.qfilter import QFilteredLaw


def logistic(x: float) -> float:
    """1/2 (1 + tanh(x / 2)) = 1 / (1 + e^-x)."""
    return 1.0 / (1.0 + math.exp(-x))


def test_gate_by_hand() -> None:
    """sigma 0.004: d = 0.012, w = 0.002. G(0) = 1/(1+e^12), G(d) = 1/2, G(d + w) =
    1/(1+e^-2), the sign of e does not matter; w = 0 means no deadband."""
    e = np.array([[0.0], [0.012], [-0.012], [0.014], [-0.010]])
    gate = deadband_gate(e, np.array([0.012]), np.array([0.002]))
    expected = [logistic(-12.0), 0.5, 0.5, logistic(2.0), logistic(-2.0)]
    np.testing.assert_allclose(gate.ravel(), expected, rtol=1e-9)
    assert gate[0, 0] == pytest.approx(6.144e-6, rel=1e-3)
    np.testing.assert_array_equal(deadband_gate(e, np.array([0.0]), np.array([0.0])), 1.0)


def record_of(error: list[float], feedforward: float, control: float) -> TrialRecord:
    n = len(error)
    reference = SampledReference(np.arange(n) * 1.0, np.zeros((n, 1)), np.zeros((n, 1)),
                                 np.zeros((n, 1)), 1.0)
    return TrialRecord(1, reference, -np.array(error).reshape(n, 1), np.zeros((n, 1)),
                       np.full((n, 1), feedforward), np.full((n, 1), control), np.zeros((n, 1)))


def test_forgetting_and_deadband_by_hand() -> None:
    """Linear law u + 1 e, memory = feed-forward 1, f = 0.9, d = 0.012, w = 0.002:
    u_next = 0.9 * 1 + G(e) e = 0.9, 0.9 + 0.5 * 0.012 = 0.906, 0.9 + 0.03 / (1 + e^-18)."""
    inner = LinearLaw(np.array([1.0]), np.array([0.0]), np.array([0.0]), Memory.FEEDFORWARD)
    law = AssistAsNeededLaw(inner, 0.9, np.array([0.012]), np.array([0.002]))
    update = law.update(record_of([0.0, 0.012, 0.03], 1.0, 5.0))
    np.testing.assert_allclose(update.feedforward.ravel(),
                               [0.9, 0.906, 0.9 + 0.03 * logistic(18.0)], rtol=0, atol=1e-15)


def test_total_input_memory_is_forgotten() -> None:
    """memory total_input: f times the whole input u_k = 5 (feed-forward 1 + feedback 4)."""
    inner = LinearLaw(np.array([1.0]), np.array([0.0]), np.array([0.0]), Memory.TOTAL_INPUT)
    law = AssistAsNeededLaw(inner, 0.5, np.array([0.0]), np.array([0.0]))  # no deadband
    update = law.update(record_of([0.0, 0.2], 1.0, 5.0))
    np.testing.assert_allclose(update.feedforward.ravel(), [2.5, 2.7], atol=1e-15)


def test_neutral_settings_give_the_inner_law_back() -> None:
    config = load_config(None, {"law": "sign"})
    from exo_ilc_ros.core.sim.experiment import Experiment

    experiment = Experiment(config)
    inner = build_law(config)
    record = experiment.run_trial(inner.initial_feedforward(experiment.reference), 1)
    neutral = AssistAsNeededLaw(inner, 1.0, np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(neutral.update(record).feedforward,
                               inner.update(record).feedforward, rtol=1e-13, atol=1e-15)


def test_build_law_puts_the_q_filter_outside() -> None:
    """Q filters what assist-as-needed produced: QFilteredLaw(AssistAsNeededLaw(linear))."""
    config = load_config(None, {"law": "linear", "q_filter.enabled": True,
                                "assist_as_needed.enabled": True,
                                "assist_as_needed.forgetting": 0.95,
                                "assist_as_needed.variability": [0.001, 0.002, 0.004]})
    law = build_law(config)
    assert isinstance(law, QFilteredLaw) and isinstance(law.inner, AssistAsNeededLaw)
    assert law.inner.forgetting == 0.95
    np.testing.assert_allclose(law.inner.deadband, [0.003, 0.006, 0.012])
    np.testing.assert_allclose(law.inner.width, [0.0005, 0.001, 0.002])
    assert not isinstance(build_law(load_config()), AssistAsNeededLaw)  # off by default


def test_analyze_loop_accounts_for_forgetting() -> None:
    """Inside the deadband F = f m: with memory = feed-forward (m = 1) |F| = f exactly; with
    total_input the paper's Nyquist peak 1.0396 (joint 1, delta 5 %) times f; outside it
    |F - (1 - f) m|."""
    loop = JointLoop(1.0 / 1.05, 16.0, 8.0, 0.01)
    freq = np.array([0.0, 10.0, 50.0])
    inside = loop.factor(freq, Memory.FEEDFORWARD, (0.0, 0.0, 0.0), forgetting=0.9)
    np.testing.assert_allclose(inside, 0.9, rtol=1e-12)
    plain = loop.factor(freq, Memory.TOTAL_INPUT, (0.0, 0.0, 0.0))
    aan = loop.factor(freq, Memory.TOTAL_INPUT, (0.0, 0.0, 0.0), forgetting=0.9)
    np.testing.assert_allclose(aan, 0.9 * plain, rtol=1e-12)  # sign law: F = m, both ends f m
    config = load_config(None, {"law": "sign", "assist_as_needed.enabled": True,
                                "assist_as_needed.forgetting": 0.95})
    analysis = analyze_loop(config)
    assert analysis.forgetting == 0.95
    assert analysis.worst() == pytest.approx(0.95 * analyze_loop(load_config()).worst(),
                                             rel=1e-9)
    assert analysis.worst() < 1.0  # forgetting 5 % removes the paper's 3.96 % growth


def test_lifted_map_ends_of_the_gate() -> None:
    from exo_ilc_ros.core.convergence.factors import lifted_map

    loop = JointLoop(1.0 / 1.05, 16.0, 8.0, 0.01)
    gains = (0.0, 0.0, 1.0)
    base = lifted_map(loop, 40, Memory.TOTAL_INPUT, (0.0, 0.0, 0.0))
    learn = lifted_map(loop, 40, Memory.TOTAL_INPUT, gains)
    np.testing.assert_allclose(lifted_map(loop, 40, Memory.TOTAL_INPUT, gains, None, 0.8, 0.0),
                               0.8 * base, atol=1e-15)
    np.testing.assert_allclose(lifted_map(loop, 40, Memory.TOTAL_INPUT, gains, None, 0.8, 1.0),
                               learn - 0.2 * base, atol=1e-15)


def test_variability_by_hand() -> None:
    """Errors 0.1, 0.3 in one trial and 0.3, 0.1 in the other: variance 0.02 at each sample
    (ddof 1), sigma = sqrt(0.02); an aborted trial is left out; one trial is not enough."""
    from exo_ilc_ros.core.learning.assist import estimate_variability

    a, b = record_of([0.1, 0.3], 0.0, 0.0), record_of([0.3, 0.1], 0.0, 0.0)
    aborted = TrialRecord(3, a.reference, np.full((2, 1), 5.0), np.zeros((2, 1)),
                          np.zeros((2, 1)), np.zeros((2, 1)), np.zeros((2, 1)), aborted_at=1)
    np.testing.assert_allclose(estimate_variability([a, b, aborted]), [math.sqrt(0.02)])
    with pytest.raises(ValueError, match="at least two"):
        estimate_variability([a, aborted])
