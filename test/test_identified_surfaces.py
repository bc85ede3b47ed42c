"""The identified patient where a user sees it (issue 28): the trial summary (the same keys every
trial, the estimate's own values), ``/ilc/trial_metrics``'s rows, ``exo-ilc analyze`` of a
``simulate --bag-dir`` bag (and of one without identification), ``exo-ilc simulate``'s final
estimate, and the therapy report's trend across two sessions."""

from __future__ import annotations

import functools
import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.analysis.session_report import exercise_run, identification_trends
from exo_ilc_ros.bag import read_bag
from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.params.config import config_dir, load_config, scenario_path
from exo_ilc_ros.core.persistence.profiles import ProfileBook
from exo_ilc_ros.core.programs.identified import SHOWN, Identified
from exo_ilc_ros.core.programs.therapy import IDENTIFICATION
from exo_ilc_ros.core.session.learning_session import TrialConclusion, run_trials
from exo_ilc_ros.nodes.messages import trial_metrics_message, trial_summary
from exo_ilc_ros.wire.protocol import key_values
from exo_ilc_ros.wire.trial_metrics import IDENTIFIED_ROWS, ROW_NAMES, index

AWARE = str(config_dir() / "patient_aware.yaml")


@functools.cache
def _spastic_run() -> tuple[Any, list[TrialConclusion]]:
    """4 trials of patient_aware.yaml with the spastic patient, and their conclusions."""
    config = load_config(overlays=[AWARE, scenario_path("spastic")], overrides={  # the
        # paper's PD gains: under patient_aware's stiffer PD the estimate is trusted later
        "control.kp": [16.0, 10.0, 10.0], "control.kd": [8.0, 5.0, 7.0],
        "control.min_stiffness": 0.0, "control.min_damping": 0.0,
        "progress_gain.position": [0.0, 0.0, 5.0], "feedforward_limit": 100.0,
        # the tanh law trusted at every speed: on the paper's one-way movement the shipped
        # 0.2 leaves Coulomb friction to the offset (test_identification_honest.py)
        "identification.reversal_speed": 0.0})
    conclusions: list[TrialConclusion] = []
    result = run_trials(config, trials=4, on_conclusion=conclusions.append)
    return result, conclusions


def test_summary_carries_the_estimate_with_the_same_keys_every_trial() -> None:
    result, conclusions = _spastic_run()
    names = list(conclusions[0].config["joint_names"])
    summaries = [key_values(trial_summary(c, names)) for c in conclusions]
    keys = [frozenset(k for k in s if k.startswith("identified/")) for s in summaries]
    assert len(set(keys)) == 1
    assert len(keys[0]) == len(names) * (4 * len(SHOWN) + 4) + 1
    used_somewhere = False
    for c, values in zip(conclusions, summaries, strict=True):
        step = c.joint_forces
        assert step is not None and result.joint_forces[c.record.trial] is step
        for j, name in enumerate(names):
            joint = step.estimate.joints[j]
            for p in SHOWN:
                for field, key in (("value", f"identified/{p}/{name}"),
                                   ("low", f"identified/{p}/low/{name}"),
                                   ("high", f"identified/{p}/high/{name}")):
                    expected = getattr(joint[p], field)
                    got = float(values[key])
                    assert got == expected or (math.isnan(got) and math.isnan(expected))
                assert values[f"identified/{p}/identifiable/{name}"] == \
                    ("true" if joint[p].identifiable else "false")
            assert values[f"identified/trustworthy/{name}"] == \
                ("true" if joint.trustworthy else "false")
            assert values[f"identified/used/{name}"] == ("true" if step.used[j] else "false")
            reason = values[f"identified/reason/{name}"]
            assert (reason == "") == (not step.reasons[j] and joint.trustworthy)
            used_somewhere |= bool(step.used[j])
        parsed = Identified.from_summary(c.record.trial, values, names)
        assert parsed is not None  # NaN != NaN: compared as filed
        assert parsed.summary_values() == Identified.from_step(step, names).summary_values()
    assert used_somewhere  # the spastic patient's estimate is in the loop within 4 trials
    first = conclusions[0].joint_forces
    assert first is not None and not first.used.any()  # trial 1: no joint trusted yet
    assert first.estimate.joints[0].reasons[0] in summaries[0][f"identified/reason/{names[0]}"]


def test_trial_metrics_draws_the_identified_parameters() -> None:
    _, conclusions = _spastic_run()
    names = list(conclusions[0].config["joint_names"])
    last = conclusions[-1]
    summary = trial_summary(last, names)
    msg = trial_metrics_message(summary, names)
    assert msg.layout.dim[0].size == len(ROW_NAMES)
    assert msg.layout.dim[0].label.endswith(",identified/viscous,identified/coulomb,"
                                            "identified/stiffness")
    assert len(msg.data) == 2 + len(ROW_NAMES) * len(names)
    assert index("identified/viscous", 0, 3) == 23  # as documented (3 joints)
    joints = last.joint_forces.estimate.joints
    for p in IDENTIFIED_ROWS:
        for j in range(len(names)):
            got = msg.data[index(f"identified/{p}", j, len(names))]
            if joints[j][p].identifiable:
                assert got == joints[j][p].value
            else:
                assert math.isnan(got)
    assert any(np.isfinite(msg.data[index("identified/viscous", j, len(names))])
               for j in range(len(names)))


def test_without_identification_no_keys_and_nan_rows() -> None:
    config = load_config()
    assert not config["identification.enabled"]
    conclusions: list[TrialConclusion] = []
    result = run_trials(config, trials=2, on_conclusion=conclusions.append)
    names = list(config["joint_names"])
    assert result.joint_forces == {}
    for c in conclusions:
        summary = trial_summary(c, names)
        assert not any(k.startswith("identified/") for k in key_values(summary))
        msg = trial_metrics_message(summary, names)
        for p in IDENTIFIED_ROWS:
            assert all(math.isnan(msg.data[index(f"identified/{p}", j, len(names))])
                       for j in range(len(names)))


def test_analyze_prints_the_identification_of_a_simulated_bag(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bags = tmp_path / "bags"
    assert main(["simulate", "--config", AWARE, "--scenario", "spastic", "--trials", "3",
                 "--bag-dir", str(bags / "aware"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "the identified patient after trial 3" in out
    assert "elbow_flexion: B " in out and "N m s/rad" in out
    assert main(["simulate", "--trials", "2", "--bag-dir", str(bags / "plain"),
                 "--quiet"]) == 0
    capsys.readouterr()
    (aware,) = (bags / "aware").iterdir()
    (plain,) = (bags / "plain").iterdir()
    run = read_bag(aware)
    names = run.joint_names
    filed = [Identified.from_summary(k, run.summaries[k], names) for k in run.completed]
    assert [f.trial for f in filed if f is not None] == [1, 2, 3]
    exported = tmp_path / "runs.json"
    assert main(["analyze", str(aware), str(plain), "--json", str(exported)]) == 0
    out = capsys.readouterr().out
    runs = json.loads(exported.read_text())["runs"]
    assert runs[0]["identified"]["trial"] == 3 and "identified" not in runs[1]
    assert out.count("the identified patient per trial") == 1  # the plain bag has none
    for name in names:
        assert f"identified {name} (95 % intervals" in out
    table = out[out.index(f"identified {names[-1]}"):].splitlines()
    assert "B (N m s/rad)" in table[1] and "trusted" in table[1]
    last = filed[-1]
    assert last is not None
    row = table[4].split()
    assert row[0] == "3"
    assert row[1] == f"{last.joints[-1]['viscous'].value:.3g}"
    assert main(["analyze", str(plain)]) == 0
    assert "identified" not in capsys.readouterr().out


def test_therapy_report_shows_the_trend_across_sessions(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    profiles, bags = tmp_path / "profiles", tmp_path / "bags"
    common = ["simulate", "--config", AWARE, "--scenario", "spastic", "--patient", "p1",
              "--profiles", str(profiles), "--trials", "2", "--quiet"]
    assert main([*common, "--new-patient", "--bag-dir", str(bags / "s1")]) == 0
    assert main([*common, "--bag-dir", str(bags / "s2")]) == 0
    capsys.readouterr()
    index = ProfileBook(profiles).index("p1", "paper_quintic")
    assert index is not None
    kept = [Identified.from_json(v["metrics"][IDENTIFICATION]) for v in index["versions"]]
    assert [k.trial for k in kept] == [2, 2]
    (second,) = (bags / "s2").iterdir()
    page = tmp_path / "report.html"
    assert main(["report", str(second), "--html", str(page), "--profiles",
                 str(profiles)]) == 0
    out = capsys.readouterr().out
    names = exercise_run(read_bag(second)).joint_names
    b = [k.joints[-1]["viscous"].value for k in kept]
    line = f"{names[-1]} damping {b[0]:.3g} -> {b[1]:.3g} N m s/rad over 2 sessions"
    identifiable = all(k.joints[-1]["viscous"].identifiable for k in kept)
    assert (line in out) == identifiable
    history = [(f"v{i}", k) for i, k in enumerate(kept, start=1)]
    lines = identification_trends(history, names)
    assert lines and all(f"paper_quintic: {x}" in out for x in lines)
    text = page.read_text()
    assert "The identified patient" in text and "Across sessions" in text
    assert all(html.escape(x) in text for x in lines)


@pytest.mark.graph
def test_the_graph_files_the_identification_on_the_summary_and_diagnostics() -> None:
    """Through the node graph (2 trials): the supervisor's summaries carry the same
    ``identified/...`` values as the in-process run, and its health on /diagnostics names the
    last estimate per joint."""
    import os

    from diagnostic_msgs.msg import DiagnosticArray

    from exo_ilc_ros.nodes.common import DIAGNOSTICS_QOS
    from exo_ilc_ros.orchestration.graph import GraphSession
    from exo_ilc_ros.wire import topics

    config = load_config(overlays=[AWARE, scenario_path("spastic")],
                         overrides={"max_trials": 2})
    names = list(config["joint_names"])
    health: list[dict[str, str]] = []

    def on_status(msg: Any) -> None:
        health.extend({kv.key: kv.value for kv in s.values} for s in msg.status
                      if any(kv.key == "identified/trial" for kv in s.values))

    with GraphSession(config, int(os.environ["ROS_DOMAIN_ID"])) as session:
        session.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_status,
                                         DIAGNOSTICS_QOS)
        session.spin_until(lambda: session.finished, 120.0, 90.0)
        session.spin_until(lambda: bool(health) and health[-1]["identified/trial"] == "2",
                           10.0)  # the health goes out at "finished"
        summaries = list(session.summaries)
    expected = run_trials(config)
    assert [s.trial for s in summaries] == [1, 2]
    for summary in summaries:
        step = expected.joint_forces[summary.trial]
        filed = {k: v for k, v in summary.values.items() if k.startswith("identified/")}
        ours = dict(Identified.from_step(step, names).summary_values())
        assert filed.keys() == ours.keys()
        for key, value in ours.items():  # the graph's samples equal in-process to ~1e-9
            if key.split("/")[1] in SHOWN and key.split("/")[2] != "identifiable":
                assert float(filed[key]) == pytest.approx(float(value), rel=1e-6, abs=1e-9,
                                                          nan_ok=True)
    assert health[-1]["identified/trial"] == "2"
    assert all(health[-1][f"identified/{n}"].startswith("B ") for n in names)


def test_a_resumed_run_files_the_restored_trials_identification(tmp_path: Path) -> None:
    """``RunResult.joint_forces`` holds every trial of a resumed run, the restored ones
    replayed as the first run identified them (a bag of it has the keys in every trial)."""
    config = load_config(overlays=[AWARE, scenario_path("spastic")], overrides={  # the
        # paper's PD gains: under patient_aware's stiffer PD the estimate is trusted later
        "control.kp": [16.0, 10.0, 10.0], "control.kd": [8.0, 5.0, 7.0],
        "control.min_stiffness": 0.0, "control.min_damping": 0.0,
        "progress_gain.position": [0.0, 0.0, 5.0], "feedforward_limit": 100.0,
        # the tanh law trusted at every speed: on the paper's one-way movement the shipped
        # 0.2 leaves Coulomb friction to the offset (test_identification_honest.py)
        "identification.reversal_speed": 0.0})
    names = list(config["joint_names"])
    first = run_trials(config, trials=2, store=tmp_path)
    resumed = run_trials(config, trials=3, store=tmp_path, resume=True)
    assert resumed.resumed == 2 and sorted(resumed.joint_forces) == [1, 2, 3]
    whole = run_trials(config, trials=3)
    for k in (1, 2, 3):
        got = Identified.from_step(resumed.joint_forces[k], names).summary_values()
        assert got == Identified.from_step(whole.joint_forces[k], names).summary_values()
        if k < 3:
            assert got == Identified.from_step(first.joint_forces[k], names).summary_values()


def test_a_graph_sessions_profile_keeps_the_replayed_estimate() -> None:
    """What ``exo-ilc run --patient`` files with the profile (the stored trials replayed) is
    the in-process session's last estimate."""
    from exo_ilc_ros.core.programs.therapy import identified_of_records

    result, _ = _spastic_run()
    config = load_config(overlays=[AWARE, scenario_path("spastic")], overrides={  # the
        # paper's PD gains: under patient_aware's stiffer PD the estimate is trusted later
        "control.kp": [16.0, 10.0, 10.0], "control.kd": [8.0, 5.0, 7.0],
        "control.min_stiffness": 0.0, "control.min_damping": 0.0,
        "progress_gain.position": [0.0, 0.0, 5.0], "feedforward_limit": 100.0,
        # the tanh law trusted at every speed: on the paper's one-way movement the shipped
        # 0.2 leaves Coulomb friction to the offset (test_identification_honest.py)
        "identification.reversal_speed": 0.0})
    names = list(config["joint_names"])
    replayed = identified_of_records(config, result.records)
    assert replayed is not None
    assert replayed.summary_values() == \
        Identified.from_step(result.joint_forces[4], names).summary_values()
    assert identified_of_records(load_config(), result.records) is None  # identification off
