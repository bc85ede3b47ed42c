"""The cuff forces of a person strapped in the exoskeleton, everywhere a trial goes: the trial
summary's ``cuff/<cuff>/<metric>`` keys, ``/ilc/trial_metrics``' cuff block, the per-sample
``/cuffs/<cuff>/wrench`` messages of a bag (in-process and recorded from the graph), the
analysis table and CSV, the session report; and the cuff-force limit through the graph
(the plant's safe hold, the supervisor's record), equal to in-process. Without a person
nothing of it appears. ``graph`` tests run the real node graph in lock-step simulated time
(the small elbow model, 1 s trials)."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core.params.config import Config, config_dir, load_config
from exo_ilc_ros.core.person.cuffs import (
    CUFF_METRICS,
    CUFFS,
    cuff_metrics,
    cuff_metrics_of_values,
    cuff_summary_values,
    first_beyond_cuff_limit,
)
from exo_ilc_ros.core.session.abort import ABORT_STOP_KEY
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.session.result import RunResult
from exo_ilc_ros.core.session.summary import RunSummary
from exo_ilc_ros.wire import topics
from exo_ilc_ros.wire.trial_metrics import HEADER_SIZE, ROW_NAMES, decode, trial_metrics

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

ELBOW = config_dir() / "myoelbow.yaml"
SHORT = {"trajectory.duration": 1.0, "musculoskeletal.settle_time": 0.2,
         "mass_uncertainty": 0.1, "max_trials": 3}
LOW_LIMIT = [150.0, 35.0]
"""A forearm limit the elbow model's trials 2 and 3 press past (trial 1 peaks at 29 N, the
learned input raises it to 36 N): those trials abort in-process."""


def _person(**overrides: Any) -> Config:
    return load_config(ELBOW, overrides={**SHORT, **overrides})


@pytest.fixture(scope="module")
def person_run() -> RunResult:
    return run_trials(_person())


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory, person_run: RunResult) -> dict[str, Path]:
    """``simulate --bag-dir``'s bags of the strapped person and of the shipped arm alone."""
    from exo_ilc_ros.bag import write_run

    root = tmp_path_factory.mktemp("bags")
    plain = load_config(overrides={"trajectory.duration": 1.0, "max_trials": 2})
    return {"person": write_run(root / "person", _person(), person_run),
            "plain": write_run(root / "plain", plain, run_trials(plain))}


def test_the_summary_keys_and_trial_metrics_carry_the_cuff_metrics_by_hand() -> None:
    """A wrench log by hand: its metrics go into the summary as exact reprs and come back;
    /ilc/trial_metrics adds them after the joints' matrix with a third layout dimension
    naming each, and a summary without them keeps the two-dimension layout."""
    wrench = np.zeros((2, 2, 6))
    wrench[0, 0, :3] = [3.0, 4.0, 0.0]  # upper arm |F| 5, then 0: RMS sqrt(12.5)
    wrench[1, 1, 3:] = [0.0, 0.0, 2.0]  # forearm |T| 2 at one of two samples
    values = dict(cuff_summary_values(wrench))
    assert values["cuff/upper_arm/peak_force_N"] == "5.0"
    assert float(values["cuff/upper_arm/rms_force_N"]) == np.sqrt(12.5)
    assert float(values["cuff/forearm/rms_torque_Nm"]) == np.sqrt(2.0)
    back = cuff_metrics_of_values(values)
    assert back is not None
    np.testing.assert_array_equal(back, cuff_metrics(wrench))
    assert cuff_summary_values(None) == [] and cuff_metrics_of_values({}) is None

    names = ["a", "b", "c"]
    plain = trial_metrics({"trial": "4"}, names, False)
    assert len(plain.dims) == 2 and len(plain.data) == HEADER_SIZE + len(ROW_NAMES) * 3
    person = trial_metrics({"trial": "4", **values}, names, False)
    assert person.data[:len(plain.data)][:1] == [4.0]
    assert len(person.dims) == 3 and person.dims[2].size == 8
    assert person.data[HEADER_SIZE + len(ROW_NAMES) * 3] == 5.0  # data[32]: upper arm peak F
    decoded = decode([d.label for d in person.dims], person.data_offset, person.data)
    assert decoded["cuff"] == {f"{c}/{m}": float(values[f"cuff/{c}/{m}"])
                               for c in CUFFS for m in CUFF_METRICS}
    assert "cuff" not in decode([d.label for d in plain.dims], plain.data_offset, plain.data)


def test_a_bag_holds_the_cuff_wrenches_and_metrics_of_every_trial(
        bags: dict[str, Path], person_run: RunResult) -> None:
    """simulate's bag of a person: every sample's wrench per cuff read back bit for bit, the
    per-trial peak / RMS (from the summaries) equal to the in-process ones; the cuff topics
    are listed only in the person's bag."""
    from exo_ilc_ros.bag import read_bag
    from exo_ilc_ros.bag.storage import read_metadata

    run = read_bag(bags["person"])
    for record in person_run.records:
        np.testing.assert_array_equal(run.trials[record.trial].cuff_wrench, record.cuff_wrench)
    local = RunSummary.from_result(person_run).cuff_forces
    assert local is not None and local.shape == (3, 2, 4)
    np.testing.assert_array_equal(run.summary().cuff_forces, local)
    listed = {t["topic_metadata"]["name"] for t in
              read_metadata(bags["person"])["topics_with_message_count"]}
    assert set(topics.CUFF_WRENCHES) <= listed
    plain = read_bag(bags["plain"])
    assert plain.summary().cuff_forces is None
    assert all(t.cuff_wrench is None for t in plain.trials.values())
    listed = {t["topic_metadata"]["name"] for t in
              read_metadata(bags["plain"])["topics_with_message_count"]}
    assert not set(topics.CUFF_WRENCHES) & listed


def test_analyze_shows_cuff_columns_only_with_a_person(
        bags: dict[str, Path], person_run: RunResult, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """exo-ilc analyze of both bags: the cuff table has the person's run only, its numbers
    the in-process peaks; the CSV has cuff columns, empty for the plain run; the plain bag
    alone shows no cuff table and no cuff column."""
    from exo_ilc_ros.cli.main import main

    csv_path = tmp_path / "both.csv"
    assert main(["analyze", str(bags["person"]), str(bags["plain"]), "--csv",
                 str(csv_path)]) == 0
    out = capsys.readouterr().out
    table = out[out.index("cuff forces on the person per trial"):]
    local = RunSummary.from_result(person_run).cuff_forces
    assert local is not None
    first_row = next(line for line in table.splitlines() if line.strip().startswith("1 |"))
    assert [float(x) for x in first_row.split("|")[1].split()] == \
        [round(float(x), 1) for x in local[0].ravel()]
    assert "plain" not in table.splitlines()[1]
    rows = list(csv.DictReader(csv_path.open()))
    assert float(rows[0]["cuff/forearm/peak_force_N"]) == local[0, 1, 0]
    assert [r["cuff/forearm/peak_force_N"] for r in rows if r["bag"].endswith("plain")] == \
        ["", ""]
    plain_csv = tmp_path / "plain.csv"
    assert main(["analyze", str(bags["plain"]), "--csv", str(plain_csv)]) == 0
    assert "cuff forces" not in capsys.readouterr().out
    assert not any(name.startswith("cuff/") for name in
                   next(csv.reader(plain_csv.open())))


def test_the_session_report_shows_the_cuff_forces_only_with_a_person(
        bags: dict[str, Path], person_run: RunResult) -> None:
    """The therapy session report: a section of the forces on the person, with the first
    trial's peak forces, only for the person's bag."""
    from exo_ilc_ros.analysis.session_report import exercise_run, render_session
    from exo_ilc_ros.bag import read_bag

    local = RunSummary.from_result(person_run).cuff_forces
    assert local is not None
    page = render_session([exercise_run(read_bag(bags["person"]))])
    section = page[page.index("Forces on the person (cuffs)"):page.index("Safety events")]
    assert f"{local[0, 0, 0]:.3g} N" in section and f"{local[0, 1, 0]:.3g} N" in section
    assert "160 N" in section  # the forearm's limit
    assert "Forces on the person" not in render_session([exercise_run(read_bag(bags["plain"]))])


def test_the_cuff_limit_abort_is_the_first_sample_past_it_in_process() -> None:
    """The low limit aborts trials 2 and 3 in-process at the first sample a cuff presses
    past it (the one rule the graph's plant and supervisor use too); two in a row stop the
    run with a message that names the cuff, its force and the limit, not the envelope."""
    result = run_trials(_person(**{"safety.cuff_force_limit": LOW_LIMIT,
                                   "abort.max_consecutive": 2}))
    assert result.aborted == [2, 3]
    for record in result.records[1:]:
        assert record.cuff_wrench is not None
        assert record.aborted_at == first_beyond_cuff_limit(record.cuff_wrench, LOW_LIMIT)
    last = result.records[-1]
    assert last.cuff_wrench is not None and last.aborted_at is not None
    force = float(np.linalg.norm(last.cuff_wrench[last.aborted_at, 1, :3]))
    assert force > LOW_LIMIT[1]
    assert f"trial 3: the forearm cuff pressed {force:.1f} N into the person" in \
        result.stop_message
    assert "safety.cuff_force_limit" in result.stop_message
    assert "error envelope" not in result.stop_message


def _recorded_graph(config: Config, path: Path) -> tuple[Any, Any]:
    """The graph's run of ``config`` with the recorder beside the supervisor, and its bag."""
    from exo_ilc_ros.bag import read_bag
    from exo_ilc_ros.orchestration.graph import run_graph
    from exo_ilc_ros.orchestration.recording import Recording

    config = config.replace({"wait_for_recorder": True})
    with Recording(config, path, "cuffs") as recording:
        graph = run_graph(config, nodes=recording.graph_nodes(), timeout=400.0)
    return graph, read_bag(recording.path)


def _trial_metrics_of(bag: Any) -> list[dict[str, object]]:
    """Every /ilc/trial_metrics message of a bag, decoded from its labels alone."""
    from exo_ilc_ros.bag.storage import read_metadata, read_topics

    streams, _, _ = read_topics(bag.path, read_metadata(bag.path), False,
                                [topics.TRIAL_METRICS], [])
    return [decode([d.label for d in msg.layout.dim], msg.layout.data_offset, list(msg.data))
            for msg in streams[topics.TRIAL_METRICS].msgs]


@pytest.mark.graph
def test_the_graph_sends_and_records_the_in_process_cuff_forces(tmp_path: Path,
                                                                 person_run: RunResult) -> None:
    """exo-ilc run's graph with the elbow model: the same trials as in-process, and their cuff
    forces equal to the last bit: in run's summary (its --json), on /ilc/trial_metrics and
    per sample in the recorder's bag."""
    graph, bag = _recorded_graph(_person(), tmp_path)
    local = RunSummary.from_result(person_run)
    assert local.cuff_forces is not None
    np.testing.assert_array_equal(graph.summary.max_abs_error, local.max_abs_error)
    np.testing.assert_array_equal(graph.summary.cuff_forces, local.cuff_forces)
    assert graph.summary.to_json()["trials"][2]["cuff_forces"] == \
        local.to_json()["trials"][2]["cuff_forces"]
    metrics = _trial_metrics_of(bag)
    assert [m["trial"] for m in metrics] == [1, 2, 3]
    for m, row in zip(metrics, local.cuff_forces, strict=True):
        cuffs = m["cuff"]
        assert isinstance(cuffs, dict)
        assert [cuffs[f"{c}/{name}"] for c in CUFFS for name in CUFF_METRICS] == \
            list(row.ravel())
    for record in person_run.records:
        np.testing.assert_array_equal(bag.trials[record.trial].cuff_wrench, record.cuff_wrench)
    np.testing.assert_array_equal(bag.summary().cuff_forces, local.cuff_forces)


@pytest.mark.graph
def test_the_graphs_cuff_limit_aborts_the_trial_as_in_process() -> None:
    """A forearm limit of 35 N through the graph: trials 2 and 3 abort at the same samples as
    in-process (the plant held the arm safe from there: the samples after the abort, the
    errors and the cuff forces are the in-process ones to the last bit), and two such aborts
    in a row stop it with the in-process message, naming the cuff."""
    from exo_ilc_ros.orchestration.graph import run_graph

    config = _person(**{"safety.cuff_force_limit": LOW_LIMIT, "abort.max_consecutive": 2})
    local = run_trials(config)
    assert local.aborted == [2, 3]
    graph = run_graph(config, timeout=400.0)
    summary = RunSummary.from_result(local)
    assert graph.summary.extra.get("aborted_trials") == [2, 3]
    assert graph.summary.extra.get("cuff_limit_aborts") == [2, 3]  # the events' reason
    assert [s.values.get("aborted_at") for s in graph.summaries] == \
        [None, *(str(r.aborted_at) for r in local.records[1:])]
    np.testing.assert_array_equal(graph.summary.max_abs_error, summary.max_abs_error)
    np.testing.assert_array_equal(graph.summary.max_abs_effort, summary.max_abs_effort)
    np.testing.assert_array_equal(graph.summary.cuff_forces, summary.cuff_forces)
    assert graph.summary.extra.get(ABORT_STOP_KEY) == local.stop_message != ""
