"""The step gain from the trials' statistics (core/learning/averaging.py, ``averaging.*``): the
local-level Kalman gain checked against its closed form, against data whose truth is known, and
in the session by hand."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core.learning.averaging import AveragingGain, averaging_of, local_level_gain
from exo_ilc_ros.core.learning.laws import FeedforwardUpdate
from exo_ilc_ros.core.loop.record import TrialRecord
from exo_ilc_ros.core.params.config import config_dir, load_config, scenario_path
from exo_ilc_ros.core.reference.trajectory import SampledReference
from exo_ilc_ros.core.session.learning_session import run_trials


def test_gain_from_the_autocorrelation_in_closed_form() -> None:
    """(KG) with (AC): rho = -1/4 is q/r = 2, K = (-2 + sqrt(12)) / 2 = sqrt(3) - 1 (the
    ARIMA(0,1,1) form: theta = 2 - sqrt(3) solves rho = -theta / (1 + theta^2), K = 1 - theta);
    rho = -1/3 is q/r = 1, K the golden ratio's 0.618; nothing repeats (rho <= -1/2): 0; only
    a drift (rho >= 0): 1."""
    gain = local_level_gain(np.array([-0.25, -1.0 / 3.0, -0.5, -0.7, 0.0, 0.3]))
    np.testing.assert_allclose(gain, [math.sqrt(3.0) - 1.0, (math.sqrt(5.0) - 1.0) / 2.0,
                                      0.0, 0.0, 1.0, 1.0], atol=1e-12)
    theta = 2.0 - math.sqrt(3.0)
    assert -theta / (1.0 + theta * theta) == pytest.approx(-0.25)


@pytest.mark.parametrize(("ratio", "expected", "tolerance"),
                         [(2.0, math.sqrt(3.0) - 1.0, 0.03), (0.0, 0.1, 0.1),
                          (math.inf, 1.0, 0.03)])
def test_gain_of_local_level_data_whose_truth_is_known(ratio: float, expected: float,
                                                       tolerance: float) -> None:
    """Targets T_k = x_k + n_k with x a random walk of variance q per trial and n white of
    variance r, 200 independent samples per trial: the estimated K is the model's steady-state
    Kalman gain, sqrt(3) - 1 for q/r = 2; pure noise (q = 0) gives about the least gain (K
    rises steeply from rho = -1/2: 0.18 at -0.49), pure drift (r = 0) the plain law."""
    rng = np.random.default_rng(3)
    rule = AveragingGain(memory=50.0, min_gain=0.1, joints=1)
    level = np.zeros((200, 1))
    q, r = (1.0, 0.0) if math.isinf(ratio) else (ratio, 1.0)
    for _ in range(300):
        level = level + math.sqrt(q) * rng.standard_normal(level.shape)
        gain = rule.observe(level + math.sqrt(r) * rng.standard_normal(level.shape))
    assert gain[0] == pytest.approx(expected, abs=tolerance)


def test_gain_is_one_until_memory_trials_are_in() -> None:
    """The first ``memory`` pairs of changes leave the law as it is, even where they
    alternate."""
    rule = AveragingGain(memory=4.0, min_gain=0.0, joints=2)
    gains = [rule.observe(np.full((5, 2), float(k % 2))) for k in range(7)]
    assert all(np.all(g == 1.0) for g in gains[:5])
    np.testing.assert_array_equal(gains[6], [0.0, 0.0])


def test_off_by_default_and_robust_unchanged() -> None:
    """``averaging.memory`` 0 (the shipped default, robust.yaml's) is no rule at all."""
    assert averaging_of(load_config(config_dir() / "robust.yaml")) is None
    assert averaging_of(load_config(config_dir() / "patient_aware.yaml")) is not None


class _TargetLaw:
    """A law whose target after trial k is the constant ``targets[k - 1]``."""

    def __init__(self, targets: list[float]) -> None:
        self.targets = targets

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        return np.zeros_like(reference.acceleration)

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        return FeedforwardUpdate(np.full_like(record.feedforward,
                                              self.targets[record.trial - 1]))


def test_session_averages_the_target_by_hand(tmp_path: Path) -> None:
    """memory 2 (lambda 1/2), targets 0, 1, 2, 1: changes 1, 1, -1 (N samples each); after
    trial 3 one pair (sums N, N, lagged N), K = 1, so trial 4 runs with T_3 = 2; after trial 4
    the sums are N/2 + N = 3N/2 (both) and lagged N/2 - N = -N/2: rho = -1/3, q/r = 1,
    K = (sqrt(5) - 1)/2, u_ff,5 = 2 + K (1 - 2) = 1.382. Without averaging it is 1. A run
    stored after 3 trials and resumed ends the same."""
    config = load_config(config_dir() / "robust.yaml",
                         {"averaging.memory": 2.0, "averaging.min_gain": 0.1})
    law = _TargetLaw([0.0, 1.0, 2.0, 1.0])
    result = run_trials(config, 0.05, 4, learning_law=law)
    np.testing.assert_allclose(result.records[3].feedforward, 2.0)
    np.testing.assert_allclose(result.final.feedforward, 2.0 - (math.sqrt(5.0) - 1.0) / 2.0,
                               atol=1e-12)
    plain = run_trials(config.replace({"averaging.memory": 0.0}), 0.05, 4, learning_law=law)
    np.testing.assert_allclose(plain.final.feedforward, 1.0)
    run_trials(config, 0.05, 3, learning_law=law, store=tmp_path)
    resumed = run_trials(config, 0.05, 4, learning_law=law, store=tmp_path, resume=True)
    assert resumed.resumed == 3
    np.testing.assert_array_equal(resumed.final.feedforward, result.final.feedforward)


def test_resume_replays_averaging_with_the_patient_in_the_loop(tmp_path: Path) -> None:
    """patient_aware.yaml under ``sensor`` with averaging over 2 trials (the shoulder's gain
    below 1 from trial 5 on, 0.1 by trial 7) and the identified forces handed over (trials 3
    and 4): a run stored after 5 trials and resumed equals the run in one go, and averaging
    changed it."""
    config = load_config(overlays=[config_dir() / "patient_aware.yaml",
                                   scenario_path("sensor")],
                         overrides={"mass_uncertainty": 0.1, "averaging.memory": 2.0})
    whole = run_trials(config, trials=9)
    run_trials(config, trials=5, store=tmp_path)
    resumed = run_trials(config, trials=9, store=tmp_path, resume=True)
    plain = run_trials(config.replace({"averaging.memory": 0.0}), trials=9)
    assert np.max(np.abs(plain.final.feedforward - whole.final.feedforward)) > 1e-3
    for a, b in zip(whole.records, resumed.records, strict=True):
        np.testing.assert_array_equal(a.effort, b.effort)
    np.testing.assert_array_equal(whole.final.feedforward, resumed.final.feedforward)
