"""The norm-optimal law (core/learning/norm_optimal.py): its model, the update (NO2) and the QP
(NO3), the cache, the robustness check, and one representative run against the linear law.

The long checks (1000 trials at 5/10/15 %, the constrained run) are in
``bench/norm_optimal_bench.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.cli.main import main as cli_main
from exo_ilc_ros.core.convergence import norm_optimal_robustness
from exo_ilc_ros.core.convergence.factors import JointLoop, lifted_map
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.learning import norm_optimal, norm_optimal_model, norm_optimal_qp
from exo_ilc_ros.core.learning.factory import build_law
from exo_ilc_ros.core.learning.laws import Memory
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import LearningSession, run_trials
from exo_ilc_ros.core.sim.experiment import Experiment

SHORT = {"trajectory.duration": 1.0, "law": "norm_optimal"}


def _config(**overrides: object) -> Config:
    return load_config(overrides={**SHORT, **overrides})


def test_per_joint_model_is_analyze_loops_lifted_map() -> None:
    """The per_joint model's G holds, per joint, the P_q of convergence.lifted_map."""
    config = _config(**{"norm_optimal.model_kind": "per_joint",
                        "norm_optimal.model_mass_uncertainty": 0.1})
    model = norm_optimal_model.lifted_model(config)
    n, count = config.joints, model.samples
    for j, (kp, kd) in enumerate(zip(config["control.kp"], config["control.kd"], strict=True)):
        loop = JointLoop(1.0 / 1.1, kp, kd, config["control.period"])
        pq = lifted_map(loop, count, Memory.FEEDFORWARD, (-1.0, 0.0, 0.0)) - np.eye(count)
        np.testing.assert_allclose(model.g[j::n, j::n], pq, rtol=0.0, atol=1e-15)
        others = [k for k in range(n) if k != j]
        assert not np.any(model.g[j::n][:, others])  # decoupled


def test_update_is_the_minimiser_of_the_cost() -> None:
    """The law's update is Phi u + L e of (NO2), and the gradient of (NO1) vanishes there."""
    config = _config(**{"norm_optimal.weight_input_size": [1e-6, 0.0, 2e-6],
                        "norm_optimal.weight_error": [1.0, 2.0, 0.5]})
    experiment = Experiment(config.with_mass_uncertainty(0.15))
    law = build_law(config)
    rng = np.random.default_rng(1)
    ff = 0.1 * rng.standard_normal(experiment.reference.position.shape)
    record = experiment.run_trial(ff, 1)
    new = law.update(record).feedforward
    m = norm_optimal_model.learning_matrices(config)
    u, e = record.feedforward.ravel(), record.error.ravel()
    np.testing.assert_allclose(new.ravel(), m.phi @ u + m.learning @ e, atol=1e-9)
    we, wd, wu = m.weights.stacked(m.model.samples)
    du = new.ravel() - u
    gradient = -m.model.g.T @ (we * (e - m.model.g @ du)) + wd * du + wu * new.ravel()
    assert np.max(np.abs(gradient)) < 1e-12


def test_learning_matrix_is_cached_per_configuration() -> None:
    """Built once per model and weights: a live change of anything else reuses it; a weight
    change builds a new one; the session's law uses the cached one."""
    config = _config()
    first = norm_optimal_model.learning_matrices(config)
    assert norm_optimal_model.learning_matrices(config.replace({"error_bound": 0.01})) is first
    assert norm_optimal_model.learning_matrices(config.replace({"memory": "feedforward"})) is first
    heavier = config.replace({"norm_optimal.weight_input_change": [1e-6, 1e-6, 1e-6]})
    second = norm_optimal_model.learning_matrices(heavier)
    assert second is not first and second.model is first.model  # same model, new weights
    session = LearningSession(config.replace({"max_trials": 2}))
    session.stage({"error_bound": 0.002})
    record = Experiment(session.config).run_trial(session.feedforward, 1)
    session.conclude(record)
    law = session.active_law
    assert isinstance(law, norm_optimal.NormOptimalLaw)
    assert law.matrices is norm_optimal_model.recursive_matrices(config)  # the law's (Riccati) form
    assert law.matrices.model is first.model


def test_exact_model_learns_almost_everything_in_one_trial() -> None:
    """Plant = model (delta = delta_m = 0): the second trial keeps < 5 % of the first's error."""
    config = _config(**{"norm_optimal.model_mass_uncertainty": 0.0})
    result = run_trials(config, 0.0, 2)
    first, second = result.max_abs_errors
    assert np.all(second < 0.05 * first)


def test_constrained_update_keeps_the_predicted_effort_within_the_limit() -> None:
    """A tight effort limit and feed-forward bound: the QP's prediction stays inside both and
    says so; with loose limits it is the unconstrained update."""
    loose = _config(**{"norm_optimal.constrained": True})
    record = Experiment(loose.with_mass_uncertainty(0.15)).run_trial(np.zeros((101, 3)), 1)
    free = build_law(loose.replace({"norm_optimal.constrained": False})).update(record)
    step = build_law(loose).update(record)
    assert step.notes == ()
    np.testing.assert_allclose(step.feedforward, free.feedforward, rtol=0.0, atol=1e-7)
    need = np.max(np.abs(record.effort), axis=0)
    tight = loose.replace({"control.effort_limit": [float(x) for x in 0.98 * need],
                           "feedforward_limit": [0.3, 0.3, 0.3]})
    law = build_law(tight)
    update = law.update(record)
    assert any("effort limit active" in n for n in update.notes)
    assert any("feed-forward bound active" in n for n in update.notes)
    assert np.max(np.abs(update.feedforward)) <= 0.3 * (1 + 1e-6)
    matrices = norm_optimal_model.learning_matrices(tight)
    constraints = norm_optimal.NormOptimalLaw.from_config(tight).constraints
    assert constraints is not None
    solved = norm_optimal_qp.solve_constrained(matrices, constraints, record)
    assert np.all(np.abs(solved.predicted_effort) <= 0.98 * need * (1 + 1e-6))


def test_bad_uncertainty_range_is_refused() -> None:
    with pytest.raises(ConfigError, match="low <= high"):
        _config(**{"norm_optimal.uncertainty_range": [0.2, 0.1]})


def test_robustness_check_and_analyze_loop(capsys: pytest.CaptureFixture[str],
                                           tmp_path: Path) -> None:
    """The shipped weights are robust over the shipped range; a plant much lighter than the
    model is not, and analyze-loop says so."""
    report = norm_optimal_robustness.robustness(_config())
    assert report.robust
    assert all(r.norm <= 1.0 + 1e-6 for r in report.lifted)
    light = norm_optimal_robustness.robustness(
        _config(**{"norm_optimal.uncertainty_range": [-0.3, -0.3]}))
    assert not light.robust
    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'
                           "ilc_supervisor:\n  ros__parameters:\n    norm_optimal:\n"
                           "      uncertainty_range: [-0.3, 0.1]\n")
    assert cli_main(["analyze-loop", "--law", "norm_optimal", "--config",
                     str(config_file)]) == 0
    out = capsys.readouterr().out
    assert "law norm_optimal, memory feedforward" in out
    assert "WARNING: the weights are not robust" in out and "delta = -0.3" in out


def test_reaches_the_bound_before_the_linear_law() -> None:
    """The shipped config at 15 % (5 s trials): every joint within the bound no later than
    with the linear law, the slowest one trial earlier (the 5/10/15 % table over 1000 trials
    is bench/norm_optimal_bench.py's)."""
    config = load_config()
    linear = run_trials(config, 0.15, 6, law="linear").iterations_to_bound().first
    ours = run_trials(config, 0.15, 6, law="norm_optimal").iterations_to_bound().first
    assert None not in linear and None not in ours
    assert all(o <= lin for o, lin in zip(ours, linear, strict=True))  # type: ignore[operator]
    assert max(ours) < max(linear)  # type: ignore[type-var]


def test_tune_norm_optimal_weights(tmp_path: Path) -> None:
    """`tune --law norm_optimal` searches Wd and delta_m (and leaves the sign problem's digest
    alone); its baseline is the config's values; the best is written as a norm_optimal config."""
    from exo_ilc_ros.analysis.tuning import TuningProblem, best_result, optimize
    from exo_ilc_ros.analysis.tuning_space import weight_params, weights_from_params

    config = _config()
    back = weights_from_params(weight_params(config), config.joints)
    assert back == {k: config[k] for k in back}
    sign = TuningProblem.from_config(config, [0.15], 4)
    assert not any(k.startswith("norm_optimal.") for k in sign.fixed_values())
    assert "law" not in sign.settings()
    problem = TuningProblem.from_config(config, [0.15], 4, law="norm_optimal")
    assert problem.digest() != sign.digest()
    study = optimize(problem, str(tmp_path / "t.journal"), 2, seed=3)
    result = best_result(study, problem)
    assert result.baseline_runs and result.best_value <= (result.baseline_value or 0.0)
    out = tmp_path / "tuned.yaml"
    assert cli_main(["tune", "--law", "norm_optimal", "--config", str(_short_yaml(tmp_path)),
                     "--mass-uncertainty", "0.15", "--trials", "4", "--budget", "0",
                     "--storage", str(tmp_path / "t.journal"), "--study-name",
                     study.study_name, "--jobs", "1", "--out", str(out)]) == 0
    assert load_config(out)["law"] == "norm_optimal"


def _short_yaml(tmp_path: Path) -> Path:
    path = tmp_path / "short.yaml"
    path.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'
                    "ilc_supervisor:\n  ros__parameters:\n    law: norm_optimal\n")
    return path


def test_active_constraints_reach_the_trial_summary_and_the_bag(tmp_path: Path) -> None:
    """What the constrained QP says (the constraints active) is not only logged: the
    supervisor's trial summary and a bag's summary carry it as ``learning_notes``."""
    from exo_ilc_ros.bag import read_bag, write_run
    from exo_ilc_ros.nodes.messages import trial_summary
    from exo_ilc_ros.wire import topics

    loose = _config(**{"norm_optimal.constrained": True, "max_trials": 2})
    trial = Experiment(loose.with_mass_uncertainty(0.15)).run_trial(np.zeros((101, 3)), 1)
    need = np.max(np.abs(trial.effort), axis=0)
    tight = loose.replace({"control.effort_limit": [float(x) for x in 0.98 * need],
                           "feedforward_limit": [0.3, 0.3, 0.3], "mass_uncertainty": 0.15})
    result = run_trials(tight)
    assert result.notes.get(1), "trial 1's update ran into the limits"
    expected = "; ".join(result.notes[1])
    session = LearningSession(tight)
    conclusion = session.conclude(result.records[0])
    values = {kv.key: kv.value for kv in trial_summary(conclusion, tight["joint_names"]).values}
    assert values[topics.LEARNING_NOTES] == expected
    bag = read_bag(write_run(tmp_path / "bag", tight, result))
    assert bag.trials[1].summary[topics.LEARNING_NOTES] == expected
    assert all(topics.LEARNING_NOTES not in t.summary for k, t in bag.trials.items()
               if not result.notes.get(k))
