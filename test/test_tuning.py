"""Tuning the sign law's schedules (Optuna) and comparing learning laws, on a short problem."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import optuna
import pytest

from exo_ilc_ros.analysis.tuning import (
    TuningError,
    TuningProblem,
    best_result,
    evaluate,
    open_study,
    optimize,
    score_errors,
)
from exo_ilc_ros.analysis.tuning_space import (
    schedule_params,
    schedule_values,
    schedules_from_params,
    suggest_schedules,
)
from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import Config, load_config

SHORT = {"trajectory.duration": 2.0}
"""A short problem: 2 s horizon (201 samples), still the paper's gains and schedules."""


def _short_file(tmp_path: Path) -> Path:
    path = tmp_path / "short.yaml"
    path.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 2.0\n')
    return path


def _scaled_levels(config: Config, factor: float) -> Config:
    return config.replace({f"schedule.{t}.{k}": [x * factor for x in config[f"schedule.{t}.{k}"]]
                           for t in ("position", "velocity", "acceleration")
                           for k in ("level_low", "level_mid", "level_high")})


def test_sampled_schedules_always_satisfy_the_schema() -> None:
    config = load_config()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0))

    def objective(trial: optuna.Trial) -> float:
        config.replace(suggest_schedules(trial, config.joints))  # validates
        return 0.0

    study.optimize(objective, n_trials=50)
    params = schedule_params(config)
    back = schedules_from_params(params, config.joints)
    for name, value in schedule_values(config).items():
        assert back[name] == pytest.approx(value), name


def test_score_counts_settling_never_settling_and_overshoot() -> None:
    bound = 0.005
    errors = np.array([[0.1, 0.1], [0.004, 0.01], [0.004, 0.004], [0.004, 0.004]])
    score = score_errors(errors, 4, bound, 20.0, 0.1)
    assert (score.first, score.settled, score.settled_cost, score.peak_penalty) == \
        ([2, 3], [2, 3], 3.0, 0.0)
    never = score_errors(np.array([[0.1, 0.1], [0.2, 0.004]]), 2, bound, 20.0, 0.1)
    assert never.settled == [None, 2]
    assert never.settled_cost == pytest.approx(2 + 2 * 3 / 4)  # K + K * share outside
    assert never.peak_penalty == pytest.approx(20.0)  # 100 % above trial 1
    stopped = score_errors(np.array([[0.1, 0.1]]), 3, bound, 20.0, 0.1, diverged=True)
    assert stopped.settled_cost == pytest.approx(6.0)


@pytest.mark.filterwarnings("ignore:Fixed parameter:UserWarning")  # the bad start is off-range
def test_tuner_never_worse_than_start_and_repairs_bad_schedules(tmp_path: Path) -> None:
    paper = load_config(None, SHORT)
    # Levels 10x the paper's chatter above the bound for good: clearly suboptimal.
    bad = _scaled_levels(paper, 10.0)
    problem = TuningProblem.from_config(bad, [0.05, 0.15], 15)
    start, _ = evaluate(bad, problem)
    assert start > 15  # never settles
    study = optimize(problem, str(tmp_path / "bad.journal"), budget=15, seed=0)
    result = best_result(study, problem)
    assert result.baseline_value == pytest.approx(start)
    assert result.best_value <= 10  # every joint settled within 10 of 15 trials, both deltas
    assert schedule_values(result.config) != schedule_values(bad)
    again, _ = evaluate(result.config, problem)
    assert again == pytest.approx(result.best_value)

    paper_problem = TuningProblem.from_config(paper, [0.05, 0.15], 15)
    paper_study = optimize(paper_problem, str(tmp_path / "paper.journal"), budget=3, seed=1)
    paper_result = best_result(paper_study, paper_problem)
    assert paper_result.baseline_value is not None
    assert paper_result.best_value <= paper_result.baseline_value


def test_a_study_of_another_problem_is_refused(tmp_path: Path) -> None:
    config = load_config(None, SHORT)
    storage = str(tmp_path / "s.journal")
    one = TuningProblem.from_config(config, [0.1], 5)
    open_study(one, storage, "shared")
    with pytest.raises(TuningError, match="another problem"):
        open_study(TuningProblem.from_config(config, [0.1], 6), storage, "shared")


def _node_parameters(path: Path, node: str) -> dict[str, Any]:
    """What rcl's own --params-file parser gives a node of that name."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(args=["--ros-args", "--params-file", str(path)], context=context)
    try:
        n = rclpy.create_node(node, context=context,
                              automatically_declare_parameters_from_overrides=True)
        try:
            return {name: p.value for name, p in n._parameters.items()}
        finally:
            n.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_cli_tune_parallel_resume_and_yaml_accepted_by_nodes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short = _short_file(tmp_path)
    out = tmp_path / "tuned.yaml"
    storage = tmp_path / "tune.journal"
    args = ["tune", "--config", str(short), "--mass-uncertainty", "0.1", "--trials", "6",
            "--jobs", "2", "--storage", str(storage), "--out", str(out), "--study-name", "t"]
    assert main([*args, "--budget", "3"]) == 0
    assert main([*args, "--budget", "2", "--jobs", "1"]) == 0  # resumes the same study
    text = capsys.readouterr().out
    assert "before" in text and "after" in text and "wrote" in text
    study = optuna.load_study(study_name="t", storage=optuna.storages.JournalStorage(
        optuna.storages.journal.JournalFileBackend(str(storage))))
    assert len(study.trials) == 5

    tuned = load_config(out)  # the validator accepts it as is
    assert tuned["trajectory.duration"] == 2.0 and tuned["law"] == "sign"
    for node in (schema.PLANT, schema.CONTROLLER, schema.SUPERVISOR):
        got = _node_parameters(out, node)
        got = {k: v for k, v in got.items() if k not in schema.ROS_BUILTIN}
        expected = tuned.section(node)
        assert set(got) == set(expected), node
        for name, value in expected.items():
            assert list(got[name]) == value if isinstance(value, list) else \
                got[name] == value, name
    assert main(["simulate", "--config", str(out), "--trials", "2", "--quiet"]) == 0


def test_compare_prints_one_table_and_writes_one_figure(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short = _short_file(tmp_path)
    tuned = tmp_path / "tuned.yaml"
    tuned.write_text(_scaled_levels(load_config(short), 0.1).to_ros_yaml("test"))
    plot = tmp_path / "compare.png"
    assert main(["compare", "--config", str(short), "--tuned", str(tuned), "--trials", "5",
                 "--mass-uncertainty", "0.05", "0.15", "--plot", str(plot), "--jobs", "1",
                 "--json", str(tmp_path / "c.json")]) == 0
    text = capsys.readouterr().out
    rows = [line for line in text.splitlines() if line.startswith(("sign", "linear"))]
    assert len(rows) == 6
    assert {row.split("  ")[0] for row in rows} == {"sign (paper)", "sign (tuned)", "linear"}
    assert sum(line.startswith("norm-optimal") for line in text.splitlines()) == 2
    assert plot.stat().st_size > 10_000
