"""The convergence analysis on cases with a known answer; its linearisation against the plant."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.analysis.loop import format_growth
from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import load_config
from exo_ilc_ros.core.convergence.factors import (
    JointLoop,
    analyze_loop,
    bands_above_one,
    lifted_map,
    packet_growth_rate,
)
from exo_ilc_ros.core.convergence.growth import fit_growth
from exo_ilc_ros.core.learning.laws import Memory
from exo_ilc_ros.core.learning.qfilter import QFilter
from exo_ilc_ros.core.sim.experiment import Experiment

PERIOD = 0.01
NONE = (0.0, 0.0, 0.0)


def test_sensitivity_by_hand_at_dc_and_nyquist() -> None:
    """ZOH double integrator, z = -1: P_q = 0 (the (z+1) zero), P_v loop gain -g K_D T/2, so
    S(-1) = 1 / (1 - g K_D T / 2); z = 1: the plant's double pole makes S(1) = 0."""
    for delta, kp, kd in ((0.0, 16.0, 8.0), (0.05, 10.0, 5.0), (0.15, 10.0, 7.0)):
        g = 1.0 / (1.0 + delta)
        loop = JointLoop(g, kp, kd, PERIOD)
        s = loop.sensitivity(np.array([-1.0 + 0j, 1.0 + 0j]))
        assert abs(s[0]) == pytest.approx(1.0 / (1.0 - g * kd * PERIOD / 2.0), rel=1e-12)
        assert abs(s[1]) == pytest.approx(0.0, abs=1e-12)


def test_paper_loop_worst_factor_and_band() -> None:
    """The paper's gains at delta 0.05: |S| peaks at Nyquist, 1/(1 - 8 * 0.01 / 2.1) = 1.0396
    for joint 1; the whole band above a few Hz exceeds 1."""
    a = analyze_loop(load_config().with_mass_uncertainty(0.05))
    assert a.worst() == pytest.approx(1.0 / (1.0 - 8.0 * PERIOD / 2.0 / 1.05), rel=1e-9)
    for j, kd in zip(a.joints, (8.0, 5.0, 7.0), strict=True):
        value, k = j.worst(False)
        assert value == pytest.approx(1.0 / (1.0 - kd * PERIOD / 2.0 / 1.05), rel=1e-9)
        assert a.frequency_hz[k] == pytest.approx(50.0)
        bands = bands_above_one(a.frequency_hz, j.unfiltered)
        assert len(bands) == 1 and 1.0 < bands[0].low_hz < 4.0 and bands[0].high_hz == 50.0


def test_feedforward_memory_without_learning_is_marginal() -> None:
    loop = JointLoop(1.0, 16.0, 8.0, PERIOD)
    f = np.linspace(0.0, 50.0, 101)
    np.testing.assert_allclose(loop.factor(f, Memory.FEEDFORWARD, NONE), 1.0)
    q = QFilter(5.0, 2, PERIOD).response(f)
    np.testing.assert_allclose(loop.factor(f, Memory.FEEDFORWARD, NONE, q), q)


def test_q_filter_removes_the_band() -> None:
    config = load_config(None, {"law": "linear", "q_filter.enabled": True})
    for delta in (0.05, 0.10, 0.15):
        a = analyze_loop(config.with_mass_uncertainty(delta))
        assert a.worst(filtered=False) > 1.02
        assert a.worst(filtered=True) < 0.2


def test_closed_form_matches_the_markov_parameters() -> None:
    """P_q(e^jw) of the closed form = DTFT of the lifted map's impulse response."""
    loop = JointLoop(1 / 1.1, 10.0, 7.0, PERIOD)
    n = 2001
    f = lifted_map(loop, n, Memory.TOTAL_INPUT, NONE)
    s_impulse = f[:, 0]  # column 0: response of the whole input to a unit u_ff at t = 0
    freq = np.array([0.3, 2.0, 17.0, 49.0])
    z = np.exp(2j * np.pi * freq * PERIOD)
    dtft = np.array([np.sum(s_impulse * zz ** -np.arange(n)) for zz in z])
    np.testing.assert_allclose(dtft, loop.sensitivity(z), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("delta", [0.0, 0.15])
def test_linearisation_matches_the_nonlinear_plant(delta: float) -> None:
    """A small perturbation p of u_ff changes the sampled whole input by S p (lifted) in the
    full nonlinear plant, within 0.02 + delta (relative 2-norm). Computed torque with the
    nominal model gives qdd = u/(1+delta) + d(q, qdot) exactly; neglected are d's variation
    with the error (O(delta): 12 % on the light elbow at 15 %) and a_N(q), c_N(q, qdot) moving
    while the torque is held over a period (O(T): ~1.4 % at delta 0)."""
    config = load_config()
    experiment = Experiment(config.with_mass_uncertainty(delta))
    n = experiment.reference.samples
    rng = np.random.default_rng(1)
    base = np.zeros((n, 3))
    p = 1e-3 * rng.normal(size=(n, 3))
    r0 = experiment.run_trial(base, 1)
    r1 = experiment.run_trial(base + p, 1)
    measured = r1.control_input - r0.control_input
    for j, (kp, kd) in enumerate(zip(config["control.kp"], config["control.kd"], strict=True)):
        loop = JointLoop(1.0 / (1.0 + delta), kp, kd, experiment.period)
        predicted = lifted_map(loop, n, Memory.TOTAL_INPUT, NONE) @ p[:, j]
        error = np.linalg.norm(measured[:, j] - predicted) / np.linalg.norm(predicted)
        assert error < 0.02 + delta, (j, error)


def test_packet_growth_rate() -> None:
    assert packet_growth_rate(np.e, 10.0) == pytest.approx(1.0 - 0.05)


def test_growth_detector_on_known_sequences() -> None:
    k = np.arange(200)
    table = np.column_stack([2.0 * 1.02 ** k, np.full(200, 3.0), 1.0 + 1e-3 * k])
    noisy = table * (1.0 + 0.01 * np.random.default_rng(0).normal(size=table.shape))
    fit = fit_growth(noisy, window=100)
    assert fit is not None
    assert fit.rate[0] == pytest.approx(np.log(1.02), rel=0.05)
    assert fit.growing.tolist() == [True, False, False]  # linear 1e-3 / 1.15 per trial < floor
    assert fit.first_trial == 101 and fit.last_trial == 200
    assert "GROWING" in format_growth(fit, ["a", "b", "c"])
    assert fit_growth(table[:5]) is None
    assert "bounded" in format_growth(fit_growth(noisy[:, 1:]), ["b", "c"])


def test_analyze_loop_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "factor.png"
    assert main(["analyze-loop", "--config", str(_robust()), "--plot", str(out)]) == 0
    text = capsys.readouterr().out
    assert "max |F| 1.03960 at  50.00 Hz" in text      # no Q: the sampled loop's band
    assert "learning stays bounded" in text             # with the robust config's Q
    assert out.stat().st_size > 10_000


def _robust() -> Path:
    return Path(__file__).resolve().parents[1] / "config" / "robust.yaml"
