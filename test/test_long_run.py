"""Long runs: the robust config stays bounded for 1000 trials; the paper's config grows, the
detector flags it, and the analysis predicts the growth rate measured in simulation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.convergence.factors import analyze_loop, packet_growth_rate
from exo_ilc_ros.core.convergence.growth import fit_growth

ROBUST = Path(__file__).resolve().parents[1] / "config" / "robust.yaml"


@pytest.mark.slow
@pytest.mark.parametrize("delta", [0.05, 0.10, 0.15])
def test_robust_config_stays_bounded_for_1000_trials(delta: float) -> None:
    config = load_config(ROBUST)
    result = run_trials(config, delta, 1000)
    errors = result.max_abs_errors
    uff = result.max_abs_feedforward
    settled = result.iterations_to_bound().settled
    assert all(s is not None and s <= 10 for s in settled), settled
    assert np.all(errors[10:] <= config["error_bound"])
    last = uff[500:]
    assert np.all(last.max(axis=0) - last.min(axis=0) <= 1e-6 * last.max(axis=0))
    fit = fit_growth(uff, window=500)
    assert fit is not None and not fit.any_growing
    assert np.all(np.abs(fit.rate) < 1e-6)
    # bounded by the Q-filter itself: the safety limit is never reached
    assert np.all(uff < 0.5 * np.asarray(config["feedforward_limit"]))


@pytest.mark.slow
def test_paper_config_grows_and_is_flagged() -> None:
    """The paper's law as printed, delta 0.05: while joints 2 and 3 stay within the bound, the
    learned input of every joint grows, at a rate below the predicted worst factor."""
    config = load_config()
    result = run_trials(config, 0.05, 90)
    errors = result.max_abs_errors
    uff = result.max_abs_feedforward
    assert np.all(errors[30:, 1:] <= config["error_bound"])
    fit = fit_growth(uff, window=60)
    assert fit is not None and fit.growing.all(), fit
    analysis = analyze_loop(config.with_mass_uncertainty(0.05))
    predicted = np.log([j.worst(False)[0] for j in analysis.joints])
    assert analysis.worst() > 1.0
    assert np.all(fit.rate <= predicted)
    assert fit.rate[0] == pytest.approx(predicted[0], rel=0.15)
    assert uff[-1, 0] > 5.0 * uff[30, 0]


@pytest.mark.slow
def test_predicted_factor_matches_the_measured_growth() -> None:
    """Linear law, memory total_input, no Q (a linear iteration, so u_ff,k+1 - u_ff,k = F^k
    (u_ff,2 - u_ff,1) exactly): the slope of log max_t |u_ff,k+1 - u_ff,k| over trials 100-200
    agrees with the analysis' log(rho) - 1/(2k) within 5 % (the neglected O(delta) and
    within-period terms, and the packet approximation) and with log(rho) itself within 15 %.
    The last sample is left out: its feed-forward is never applied, so it only integrates the
    final error (a linear drift, not the band's growth)."""
    delta = 0.05
    config = load_config(None, {"law": "linear"})
    result = run_trials(config, delta, 201)
    uff = np.array([r.feedforward[:-1] for r in result.records])
    step = np.max(np.abs(np.diff(uff, axis=0)), axis=1)
    k = np.arange(100, 200)
    measured = np.array([np.polyfit(k, np.log(step[100:200, j]), 1)[0] for j in range(3)])
    assert np.all(result.max_abs_errors[5:] <= config["error_bound"])  # the error looks fine
    analysis = analyze_loop(config.with_mass_uncertainty(delta))
    rho = np.array([j.worst(False)[0] for j in analysis.joints])
    packet = np.array([packet_growth_rate(r, 150.0) for r in rho])
    np.testing.assert_allclose(measured, packet, rtol=0.05)
    np.testing.assert_allclose(measured, np.log(rho), rtol=0.15)
