"""The README's live change (`exo-ilc param set` from another terminal while `exo-ilc run` runs)
changes what the run shows: applied in-process from a trial on (what the graph does at that
trial boundary, the same trials: test_graph.py), the run's table marks that row and its rows
from there differ from the run without the change. The command is read from the README."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np

from exo_ilc_ros.analysis.report import format_run_events, format_trial_table
from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.params.config import load_ros_yaml
from exo_ilc_ros.core.session.summary import RunSummary

ROOT = Path(__file__).resolve().parents[1]
FROM_TRIAL = 4


def readme_live_change() -> tuple[str, str, object]:
    """(node, parameter, value) of the README's ``exo-ilc param set``."""
    lines = [line for line in (ROOT / "README.md").read_text().splitlines()
             if "exo-ilc param set " in line]
    assert len(lines) == 1, lines
    words = shlex.split(lines[0].split("exo-ilc ", 1)[1], comments=True)
    assert words[:2] == ["param", "set"]
    node, name, text = words[2:5]
    return node, name, load_ros_yaml(text)


def test_the_readmes_live_change_shows_in_the_runs_table() -> None:
    node, name, value = readme_live_change()
    assert node == "ilc_supervisor"
    config = load_config(overrides={"trajectory.duration": 1.0})
    names = config["joint_names"]
    plain = run_trials(config, 0.1, 8)
    changed = run_trials(config, 0.1, 8, changes={FROM_TRIAL: {name: value}})
    before = FROM_TRIAL - 1  # trials 1..3 ran before the change
    np.testing.assert_array_equal(changed.max_abs_errors[:before], plain.max_abs_errors[:before])
    # the change acts: the rows from the trial it applies to are not the plain run's
    assert np.any(changed.max_abs_errors[before:] != plain.max_abs_errors[before:])
    summary = RunSummary.from_result(changed)
    table = format_trial_table([summary], names).splitlines()
    plain_table = format_trial_table([RunSummary.from_result(plain)], names).splitlines()
    rows = [k for k, (a, b) in enumerate(zip(table, plain_table, strict=True)) if a != b]
    assert rows, "the change shows in no row of the run's table"
    row = next(line for line in table if line.startswith(f"{FROM_TRIAL:>5} "))
    assert f"{value} from here" in row  # the row the change first applies to says so
    assert f"live change from trial {FROM_TRIAL}: {node} {name} = \"{value}\"" in \
        format_run_events([summary])
