"""The Q-filter: DC gain 1, zero phase, attenuation above the cut-off, edge handling, wrapper."""

from __future__ import annotations

import numpy as np
import pytest

from exo_ilc_ros.core import load_config
from exo_ilc_ros.core.convergence.factors import JointLoop, lifted_map
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.learning.factory import build_law
from exo_ilc_ros.core.learning.laws import FeedforwardUpdate, Memory, SignLaw
from exo_ilc_ros.core.learning.qfilter import QFilter, QFilteredLaw
from exo_ilc_ros.core.loop.record import TrialRecord
from exo_ilc_ros.core.reference.build import build_reference

PERIOD = 0.01
SAMPLES = 501
T = np.arange(SAMPLES) * PERIOD


@pytest.fixture(scope="module")
def qf() -> QFilter:
    return QFilter(5.0, 2, PERIOD)


def test_dc_gain_is_one_up_to_the_ends(qf: QFilter) -> None:
    x = np.full((SAMPLES, 3), [1.0, -2.5, 0.3])
    np.testing.assert_allclose(qf.apply(x), x, atol=1e-12)
    assert qf.response(np.array([0.0]))[0] == pytest.approx(1.0)


def test_response_is_one_half_at_the_cutoff_and_falls_above(qf: QFilter) -> None:
    q = qf.response(np.array([0.5, 5.0, 20.0, 40.0]))
    assert q[0] == pytest.approx(1.0, abs=1e-3)
    assert q[1] == pytest.approx(0.5, abs=1e-9)   # |H|^2 at the Butterworth cut-off
    assert q[2] < 5e-3 and q[3] < 3e-4            # -80 dB/decade: (5/20)^4 = 3.9e-3


def test_zero_phase_sine_keeps_its_timing(qf: QFilter) -> None:
    f = 1.0
    x = np.sin(2 * np.pi * f * T)
    y = qf.apply(x)
    inner = slice(100, 400)  # away from the ends
    gain = qf.response(np.array([f]))[0]
    np.testing.assert_allclose(y[inner], gain * x[inner], atol=2e-3)
    # a phase lag would show as a cosine component
    assert abs(np.dot(y[inner], np.cos(2 * np.pi * f * T[inner]))) < 1e-2


def test_zero_phase_symmetric_impulse_response(qf: QFilter) -> None:
    x = np.zeros(SAMPLES)
    x[250] = 1.0
    y = qf.apply(x)
    np.testing.assert_allclose(y[250 - 100:250], y[251:251 + 100][::-1], atol=1e-12)
    assert np.argmax(y) == 250


def test_attenuation_above_cutoff_matches_the_response(qf: QFilter) -> None:
    for f in (10.0, 20.0, 45.0):
        x = np.sin(2 * np.pi * f * T)
        y = qf.apply(x)
        amplitude = np.max(np.abs(y[100:400]))
        assert amplitude == pytest.approx(qf.response(np.array([f]))[0], rel=0.05, abs=1e-6)


def test_filter_never_amplifies_a_learned_input(qf: QFilter) -> None:
    """The filter as a (N+1)x(N+1) matrix: 2-norm ~1 (even padding)."""
    matrix = qf.apply(np.eye(SAMPLES))
    assert np.linalg.norm(matrix, 2) < 1.01


def test_edge_handling_makes_the_lifted_map_a_contraction(qf: QFilter) -> None:
    """Even padding: spectral radius of Q S ~0.85 for the paper's loop; odd padding (scipy's
    default) leaves an edge mode at ~0.99 (the unapplied last sample keeps integrating)."""
    from scipy import signal

    loop = JointLoop(1 / 1.05, 16.0, 8.0, PERIOD)
    with_q = lifted_map(loop, SAMPLES, Memory.TOTAL_INPUT, (0.0, 0.0, 0.0), qf)
    radius = np.max(np.abs(np.linalg.eigvals(with_q)))
    assert radius < 0.86
    plain = lifted_map(loop, SAMPLES, Memory.TOTAL_INPUT, (0.0, 0.0, 0.0))
    odd = signal.sosfiltfilt(qf.sos, np.eye(SAMPLES), axis=0, padtype="odd") @ plain
    assert np.max(np.abs(np.linalg.eigvals(odd))) > 0.98


def test_high_order_low_cutoff_stays_stable() -> None:
    """Second-order sections: an order-8 filter at 0.05 Hz still passes a constant exactly."""
    x = np.ones((SAMPLES, 1))
    np.testing.assert_allclose(QFilter(0.05, 8, PERIOD).apply(x), x, atol=1e-9)


def test_cutoff_must_be_below_nyquist() -> None:
    with pytest.raises(ValueError, match="Nyquist"):
        QFilter(50.0, 2, PERIOD)
    with pytest.raises(ConfigError, match=r"q_filter\.cutoff_hz"):
        load_config(None, {"q_filter.cutoff_hz": 60.0})


class _Const:
    def __init__(self, value: np.ndarray) -> None:
        self.value = value

    def initial_feedforward(self, reference: object) -> np.ndarray:
        return np.zeros_like(self.value)

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        return FeedforwardUpdate(self.value.copy(), np.ones((3, 3)))


def test_wrapper_filters_bounds_and_passes_levels(qf: QFilter) -> None:
    rng = np.random.default_rng(0)
    raw = 3.0 + rng.normal(size=(SAMPLES, 3))
    law = QFilteredLaw(_Const(raw), qf, np.array([np.inf, 3.5, 1.0]))
    out = law.update(None)  # type: ignore[arg-type]
    filtered = qf.apply(raw)
    np.testing.assert_allclose(out.feedforward[:, 0], filtered[:, 0])
    assert np.max(out.feedforward[:, 1]) <= 3.5 and np.max(np.abs(out.feedforward[:, 2])) <= 1.0
    # white noise: sqrt(mean Q^2) ~ sqrt(0.1) of it passes a 5 Hz filter at 50 Hz Nyquist
    assert np.std(out.feedforward[:, 0]) < 0.4 * np.std(raw[:, 0])
    np.testing.assert_array_equal(out.levels, np.ones((3, 3)))


def test_build_law_wraps_only_when_asked() -> None:
    paper = load_config()
    assert isinstance(build_law(paper), SignLaw)  # the paper's config: no Q, no bound
    robust = load_config(None, {"q_filter.enabled": True, "feedforward_limit": [0.0, 5.0, 0.0]})
    law = build_law(robust)
    assert isinstance(law, QFilteredLaw) and isinstance(law.inner, SignLaw)
    assert law.qfilter is not None and law.qfilter.cutoff_hz == robust["q_filter.cutoff_hz"]
    assert law.feedforward_limit is not None
    np.testing.assert_array_equal(law.feedforward_limit, [np.inf, 5.0, np.inf])
    ref = build_reference(robust)
    np.testing.assert_array_equal(law.initial_feedforward(ref), np.zeros_like(ref.position))
