"""Bags and offline analysis: round trip, independent reader, sqlite3, SIGKILL, figures.

In-process tests write bags with ``write_run`` (the graph's topics and messages, no DDS); the
``graph`` tests run the real bag_recorder process against the real node graph.
"""

from __future__ import annotations

import glob
import json
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from test_bag_integrity import assert_bag_verifiable

from exo_ilc_ros.analysis.figures import convergence_figure, tracking_figure
from exo_ilc_ros.bag import (
    BagReadError,
    BagWriteError,
    BagWriter,
    read_bag,
    trials_filed,
    write_run,
)
from exo_ilc_ros.bag import messages as bag_messages
from exo_ilc_ros.bag.provenance import CONFIG_JSON, CONFIG_YAML, RECORDED_BY, read_provenance
from exo_ilc_ros.cli.main import main as exo_ilc
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.session.result import RunResult
from exo_ilc_ros.core.session.summary import RunSummary
from exo_ilc_ros.wire import topics
from exo_ilc_ros.wire.cdr import read_float64_array
from exo_ilc_ros.wire.qos import offered_qos

TRIALS = 5
SHORT = {"trajectory.duration": 1.0, "max_trials": TRIALS}
"""101 samples per trial keep the tests short."""


@pytest.fixture(scope="module")
def config() -> Config:
    return load_config(overrides=SHORT)


@pytest.fixture(scope="module")
def result(config: Config) -> RunResult:
    return run_trials(config, 0.10)


@pytest.fixture(scope="module")
def mcap_bag(tmp_path_factory: pytest.TempPathFactory, config: Config,
             result: RunResult) -> Path:
    return write_run(tmp_path_factory.mktemp("bags") / "run_mcap", config, result,
                     split_every=2)


def test_a_bag_from_before_a_parameter_was_added_keeps_its_config(
        mcap_bag: Path, tmp_path: Path, result: RunResult) -> None:
    """A bag whose recorded config lacks parameters added since (the safe hold's gains) or
    names one since removed: its config is kept, the added ones at today's defaults and the
    removed one left out, each said in a note; the table and a replay are as before."""
    import shutil

    from exo_ilc_ros.bag.provenance import CONFIG_JSON
    from exo_ilc_ros.bag.replay import replay_plan

    old = tmp_path / "old"
    shutil.copytree(mcap_bag, old)
    meta = old / "metadata.yaml"
    document = yaml.safe_load(meta.read_text())
    custom = document["rosbag2_bagfile_information"]["custom_data"]
    values = json.loads(custom[CONFIG_JSON])
    for key in ("safety.hold_kp", "safety.hold_kd"):
        del values[key]
    values["safety.retired_key"] = 1.0
    custom[CONFIG_JSON] = json.dumps(values)
    meta.write_text(yaml.safe_dump(document))

    recorded = read_bag(mcap_bag).provenance.config
    run = read_bag(old)
    assert run.provenance.config is not None and recorded is not None
    assert run.provenance.config.values == recorded.values  # the defaults are today's
    assert any("without safety.hold_kp, safety.hold_kd" in n and "today's defaults" in n
               for n in run.notes), run.notes
    assert any("safety.retired_key" in n and "left out" in n for n in run.notes), run.notes
    assert_same_table(run.summary(), RunSummary.from_result(result))
    plan = replay_plan(run)
    assert plan.config.values == recorded.replace({"max_trials": plan.trials}).values
    assert any("today's defaults" in n for n in plan.notes)


def assert_same_table(summary: RunSummary, reference: RunSummary, tol: float = 1e-12) -> None:
    assert summary.max_abs_error.shape == reference.max_abs_error.shape
    np.testing.assert_allclose(summary.max_abs_error, reference.max_abs_error, rtol=0, atol=tol)
    for got, want in ((summary.max_abs_feedforward, reference.max_abs_feedforward),
                      (summary.max_abs_effort, reference.max_abs_effort)):
        assert got is not None and want is not None
        np.testing.assert_allclose(got, want, rtol=0, atol=tol)
    assert summary.iterations_to_bound() == reference.iterations_to_bound()
    assert summary.mass_uncertainty == reference.mass_uncertainty
    assert summary.law == reference.law


def test_round_trip_equals_the_runs_own_table(mcap_bag: Path, config: Config,
                                              result: RunResult) -> None:
    run = read_bag(mcap_bag)
    assert_same_table(run.summary(), RunSummary.from_result(result))
    assert run.summary().extra["sources"] == ["samples"] * TRIALS
    assert run.completed == list(range(1, TRIALS + 1)) and not run.incomplete
    assert run.joint_names == config["joint_names"]
    assert not run.notes
    for record in result.records:
        trial = run.trials[record.trial]
        np.testing.assert_array_equal(trial.position, record.position)
        np.testing.assert_array_equal(trial.velocity, record.velocity)
        np.testing.assert_array_equal(trial.command, record.effort)
        np.testing.assert_array_equal(trial.effort[1:], record.effort[:-1])
        assert trial.feedforward is not None
        np.testing.assert_array_equal(trial.feedforward, record.feedforward)
        np.testing.assert_array_equal(trial.error, record.error)


def test_provenance_is_enough_to_rerun(mcap_bag: Path, config: Config, result: RunResult,
                                       tmp_path: Path) -> None:
    info = yaml.safe_load((mcap_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    prov = read_provenance(info["custom_data"])
    assert prov.version and prov.recorded_by == "exo-ilc simulate"
    assert prov.mass_uncertainty == 0.10 and prov.law == "sign"
    assert prov.options["memory"] == config["memory"]
    assert prov.options["control.period"] == config["control.period"]
    assert prov.config is not None
    assert prov.config.values == config.replace({"mass_uncertainty": 0.10}).values
    assert prov.trials_completed == TRIALS
    out = tmp_path / "from_bag.yaml"
    assert exo_ilc(["analyze", str(mcap_bag), "--quiet", "--config-out", str(out)]) == 0
    rerun = run_trials(load_config(out))
    np.testing.assert_array_equal(rerun.max_abs_errors, result.max_abs_errors)


def test_independent_mcap_reader_reads_every_message(mcap_bag: Path, config: Config) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    info = yaml.safe_load((mcap_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    expected = {t["topic_metadata"]["name"]: t["message_count"]
                for t in info["topics_with_message_count"]}
    assert set(expected) == set(topics.BAG_TYPES)  # every recorded topic listed, as rosbag2 does
    assert expected.pop(topics.PARAMETER_EVENTS) == 0  # the graph's own: none in-process
    files = info["relative_file_paths"]
    assert len(files) == TRIALS // 2 + 1  # split every 2 trials, the rest in the last file
    counts: dict[str, int] = {}
    for name in files:
        with open(mcap_bag / name, "rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            assert reader.get_header().profile == "ros2"
            for _, channel, _, decoded in reader.iter_decoded_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
                if channel.topic == topics.JOINT_STATES:
                    assert list(decoded.name) == config["joint_names"]
                    assert len(decoded.position) == config.joints
    assert counts == expected
    assert counts[topics.JOINT_STATES] == TRIALS * 101
    assert counts[topics.TF] == TRIALS * 101  # the arm's view: one /tf per sample
    assert counts[topics.ROBOT_DESCRIPTION] == counts[topics.REFERENCE_DESCRIPTION] == 1
    assert sum(counts.values()) == info["message_count"]


def _old_layout_bag(bag: Path, out: Path) -> Path:
    """``bag`` rewritten as the recorder wrote bags before issue 26: one file, wall-clock log
    times (DDS receipt: a run of 5 s sim time logged within about 1.5 s, topics interleaved
    with jitter), /clock at every sample, no /diagnostics, no /ilc/trial_metrics, trial 1's
    summary without the ``level/`` keys, no /robot_description or /tf, and only topics with
    messages listed."""
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    kept: list[tuple[int, str, bytes]] = []
    for file in sorted(glob.glob(str(bag / "*.mcap"))):
        with open(file, "rb") as handle:
            for _, channel, message in make_reader(handle).iter_messages():
                if channel.topic in (topics.DIAGNOSTICS, topics.TRIAL_METRICS, topics.CLOCK,
                                     *topics.VIEW_TYPES):
                    continue
                data = message.data
                if channel.topic in (topics.TRIAL_SUMMARY, topics.TRIAL_EVENTS):
                    msg = bag_messages.typestore().deserialize_cdr(data, topics.TYPES[
                        topics.TRIAL_SUMMARY])
                    for status in msg.status:
                        status.values = [kv for kv in status.values if kv.value != "nan"]
                    data = bag_messages.serialize(msg, topics.TYPES[topics.TRIAL_SUMMARY])
                kept.append((message.log_time, channel.topic, bytes(data)))
                if channel.topic == topics.JOINT_STATES:
                    kept.append((message.log_time, topics.CLOCK,
                                 bag_messages.clock(message.log_time)))
    rng = np.random.default_rng(3)
    wall = 1_796_000_000 * 10**9
    old = [(wall + int(stamp * 0.3) + int(rng.integers(0, 200_000)), topic, data)
           for stamp, topic, data in kept]
    old.sort(key=lambda item: item[0])
    present = {topic for _, topic, _ in old}
    with BagWriter(out, custom_data=info["custom_data"]) as writer:
        for topic in topics.TYPES:
            if topic in present:
                writer.add_topic(topic, topics.TYPES[topic], offered_qos(topic))
        writer.write_many(old)
    return out


def test_analyze_reads_an_old_layout_bag_as_before(tmp_path: Path, mcap_bag: Path) -> None:
    """A bag of the old layout (wall-clock log times, /clock every sample, no /diagnostics,
    one file) analyses to the same table as the new layout's."""
    old = _old_layout_bag(mcap_bag, tmp_path / "old")
    info = yaml.safe_load((old / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert len(info["relative_file_paths"]) == 1
    assert info["starting_time"]["nanoseconds_since_epoch"] > 10**18  # wall clock
    listed = {t["topic_metadata"]["name"] for t in info["topics_with_message_count"]}
    assert topics.DIAGNOSTICS not in listed and topics.TRIAL_METRICS not in listed
    old_run, new_run = read_bag(old), read_bag(mcap_bag)
    assert sorted(old_run.trials) == sorted(new_run.trials)
    assert_same_table(old_run.summary(), new_run.summary(), tol=0.0)
    assert exo_ilc(["analyze", str(old), "--quiet"]) == 0


def test_every_storage_file_carries_the_runs_configuration(mcap_bag: Path) -> None:
    """Each MCAP file's own rosbag2 metadata record holds the run's config and provenance, as
    metadata.yaml does (a file copied alone still says what run it is)."""
    info = yaml.safe_load((mcap_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert len(info["relative_file_paths"]) > 1
    for name in info["relative_file_paths"]:
        with open(mcap_bag / name, "rb") as handle:
            (record,) = [m for m in make_reader(handle).iter_metadata() if m.name == "rosbag2"]
        split = yaml.safe_load(record.metadata["serialized_metadata"])
        for key in (CONFIG_JSON, CONFIG_YAML, RECORDED_BY):
            assert split["custom_data"][key] == info["custom_data"][key], (name, key)
        assert split["relative_file_paths"] == [name]


def test_sqlite3_bag_analyses_identically(tmp_path: Path, mcap_bag: Path, config: Config,
                                          result: RunResult) -> None:
    bag = write_run(tmp_path / "run_db3", config, result, storage="sqlite3")
    stored = [p.suffix for p in bag.iterdir() if p.name != "metadata.yaml"]
    assert stored == [".db3"] * len(stored) and len(stored) >= TRIALS  # one file per trial
    sqlite_run, mcap_run = read_bag(bag), read_bag(mcap_bag)
    assert sqlite_run.storage == "sqlite3" and mcap_run.storage == "mcap"
    assert_same_table(sqlite_run.summary(), mcap_run.summary(), tol=0.0)


def test_bag_without_events_or_provenance_uses_summaries(tmp_path: Path, mcap_bag: Path,
                                                         result: RunResult) -> None:
    """A `ros2 bag record` of fewer topics: trials cut at the summaries' stamps."""
    from rosbags.highlevel import AnyReader

    bag = tmp_path / "partial"
    keep = {topics.JOINT_STATES, topics.TRIAL_SUMMARY, topics.FEEDFORWARD}
    with AnyReader([mcap_bag]) as reader, BagWriter(bag) as writer:
        for conn in reader.connections:
            if conn.topic in keep:
                writer.add_topic(conn.topic, conn.msgtype)
        for conn, stamp, raw in reader.messages([c for c in reader.connections
                                                 if c.topic in keep]):
            writer.write(conn.topic, stamp, raw)
    run = read_bag(bag)
    assert any("summaries' stamps" in note for note in run.notes)
    np.testing.assert_array_equal(run.summary().max_abs_error, result.max_abs_errors)
    assert run.mass_uncertainty == 0.10 and run.law == "sign"


def test_writer_refuses_existing_bag_and_undeclared_topic(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "b") as writer, pytest.raises(BagWriteError, match="undeclared"):
        writer.write("/nope", 1, b"")
    with pytest.raises(BagWriteError, match="exists already"):
        BagWriter(tmp_path / "b").open()
    with pytest.raises(BagReadError, match=r"metadata\.yaml"):
        read_bag(tmp_path)


def test_batched_writes_give_the_same_file_as_one_by_one(tmp_path: Path) -> None:
    """write_many (the recorder's path: one batch per drain) writes the very bytes the
    per-message write does, across chunk boundaries (> 1 MiB), with topics interleaved and
    timestamps out of order, for MCAP and sqlite3 storage."""
    rng = np.random.default_rng(3)
    messages = [(int(t), topic, rng.bytes(int(size)))
                for t, topic, size in zip(rng.integers(10**9, 2 * 10**9, 12000),
                                          rng.choice([topics.JOINT_STATES, topics.CLOCK,
                                                      topics.EFFORT_COMMANDS], 12000),
                                          rng.integers(0, 400, 12000), strict=True)]
    for storage in ("mcap", "sqlite3"):
        one, many = tmp_path / storage / "one" / "bag", tmp_path / storage / "many" / "bag"
        for path in (one, many):
            with BagWriter(path, storage=storage) as writer:
                for topic in topics.TYPES:
                    writer.add_topic(topic, topics.TYPES[topic])
                if path == one:
                    for t, topic, data in messages:
                        writer.write(topic, t, data)
                    writer.split()
                    writer.write(topics.CLOCK, 5, b"x")
                else:
                    for start in range(0, len(messages), 997):  # batches of any size
                        assert writer.write_many(messages[start:start + 997]) == \
                            len(messages[start:start + 997])
                    assert writer.write_many([]) == 0
                    writer.split()
                    writer.write_many([(5, topics.CLOCK, b"x")])
        if storage == "mcap":
            files = sorted(p.name for p in one.iterdir())
            assert files == sorted(p.name for p in many.iterdir()) and len(files) == 3
            for name in files:
                assert (one / name).read_bytes() == (many / name).read_bytes(), name
            assert len((one / files[0]).read_bytes()) > 2 * 2**20  # several chunks
        from rosbags.highlevel import AnyReader

        for path in (one, many):
            with AnyReader([path]) as reader:
                read = sorted((t, c.topic, bytes(d)) for c, t, d in reader.messages())
            assert read == sorted([*messages, (5, topics.CLOCK, b"x")])
    with BagWriter(tmp_path / "b") as writer, pytest.raises(BagWriteError, match="undeclared"):
        writer.write_many([(1, "/nope", b"")])


def test_metadata_from_cached_pieces_is_one_dump(tmp_path: Path) -> None:
    """metadata.yaml (and each file's own metadata) are assembled from pieces dumped once; the
    text equals one yaml.dump of the whole, split after split, with custom data that needs
    quoting and spans lines, and custom data that changes."""
    from exo_ilc_ros.bag.metadata_yaml import INFO_KEY
    from exo_ilc_ros.bag.metadata_yaml import MetadataYaml as _MetadataYaml
    from exo_ilc_ros.bag.metadata_yaml import dump_yaml as _dump

    custom = {"config": "a: 1\nb: 'two'\n  c: \"3\"\n", "empty": "", "colon": "x: y # z"}
    with BagWriter(tmp_path / "b", custom_data=custom) as writer:
        for topic in topics.TYPES:
            writer.add_topic(topic, topics.TYPES[topic])
        pieces, whole = _MetadataYaml(INFO_KEY), _MetadataYaml(None)
        for k in range(6):
            writer.write(topics.CLOCK, 10 * k + 1, b"c")
            if k % 2:
                writer.write(topics.JOINT_STATES, 10 * k + 2, b"j")
            writer.set_custom_data("trials_completed", str(k))
            writer.split()
            info = writer._metadata(writer._files, {t.name: t.count
                                                    for t in writer._topics.values()},
                                    writer.custom_data)
            text = (tmp_path / "b" / "metadata.yaml").read_text()
            assert text == _dump({INFO_KEY: info}) == pieces.dump(info)
            assert whole.dump(info) == _dump(info)
            assert yaml.safe_load(text)[INFO_KEY]["custom_data"]["config"] == custom["config"]
        assert _MetadataYaml(None).dump({"files": [], "custom_data": None}) == \
            _dump({"files": [], "custom_data": None})


def test_recording_runs_the_recorder_in_the_supervisors_process(tmp_path: Path,
                                                                config: Config) -> None:
    """By default the recorder joins ilc_supervisor's process (one container, its parameters
    from a params file of its own so they reach no other node); isolated, it is one more
    process. -p arguments cannot be composed (they would reach every node of the process)."""
    from exo_ilc_ros.orchestration.launcher import GRAPH_NODES, NodeSpec, composed
    from exo_ilc_ros.orchestration.recording import Recording

    with Recording(config, tmp_path, "r") as recording:
        names = [spec.name for spec in recording.graph_nodes()]
        assert names == ["plant_simulator", "computed_torque_controller",
                         "ilc_supervisor+bag_recorder"]
        command = recording.graph_nodes()[-1].command("graph.yaml")
        assert command[1:5] == ["-m", "exo_ilc_ros.nodes.container", "ilc_supervisor",
                                "bag_recorder"]
        assert command[5:] == ["--ros-args", "--params-file", "graph.yaml", "--params-file",
                               str(recording.params_file)]
        params = yaml.safe_load(Path(str(recording.params_file)).read_text())
        assert params["bag_recorder"]["ros__parameters"]["bag_path"] == str(recording.path)
        isolated = recording.graph_nodes(isolated=True)
        assert isolated[:3] == list(GRAPH_NODES) and isolated[3].name == "bag_recorder"
    with pytest.raises(ValueError, match="every node"):
        composed([GRAPH_NODES[2], NodeSpec("bag_recorder", "m", ("-p", "a:=1"))])


def test_killed_writer_leaves_every_finished_trial(tmp_path: Path, config: Config,
                                                   result: RunResult) -> None:
    """SIGKILL in the middle of trial 4 (no close, no metadata update): trials 1-3 analyse."""
    bag = tmp_path / "killed"
    script = textwrap.dedent(f"""
        import os, signal
        from exo_ilc_ros.bag import run_writer
        from exo_ilc_ros.core.params.config import load_config
        from exo_ilc_ros.core.session.learning_session import run_trials
        real = run_writer.messages.trial_event
        def event(ns, kind, trial, values=()):
            if kind == "start" and trial == 4:
                os.kill(os.getpid(), signal.SIGKILL)
            return real(ns, kind, trial, values)
        run_writer.messages.trial_event = event
        config = load_config(overrides={SHORT!r})
        run_writer.write_run({str(bag)!r}, config, run_trials(config, 0.10), split_every=1)
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]
    assert (bag / ".splits").is_dir()  # the interrupted file, never listed
    run = read_bag(bag)
    assert run.completed == [1, 2, 3]
    np.testing.assert_array_equal(run.summary().max_abs_error, result.max_abs_errors[:3])


def test_reader_tells_envelope_aborts_reruns_and_resume_apart(tmp_path: Path, mcap_bag: Path,
                                                               result: RunResult) -> None:
    """A synthetic bag of a resumed run (trials 3-5 of the module's run): a ``resumed`` event
    (no trial number), a watchdog abort of a first attempt at trial 4 (run again: the last start
    counts), and an envelope abort of trial 5 (``reason: error_envelope``, kept, aborted_at)."""
    from rosbags.highlevel import AnyReader

    from exo_ilc_ros.bag import messages

    period_ns = 10_000_000
    samples = 101

    def t0(k: int) -> int:
        return ((k - 1) * samples + 1) * period_ns

    end5 = t0(5) + (samples - 1) * period_ns
    injected = [
        (t0(3) - 3, messages.trial_event(t0(3) - 3, "resumed", 0, [("trials", "2")])),
        (t0(4) - 2, messages.trial_event(t0(4) - 2, "start", 4)),
        (t0(4) - 1, messages.trial_event(t0(4) - 1, "aborted", 4,
                                         [("reason", "watchdog"), ("watchdog_trips", "1")])),
        (end5 - 1, messages.trial_event(end5, "aborted", 5,
                                        [("reason", "error_envelope"), ("aborted_at", "60")])),
    ]
    bag = tmp_path / "resumed"
    with AnyReader([mcap_bag]) as reader, BagWriter(bag) as writer:
        for conn in reader.connections:
            writer.add_topic(conn.topic, conn.msgtype)
        pending = sorted(injected, key=lambda item: item[0])
        for conn, stamp, raw in reader.messages():
            if stamp < t0(3) and conn.topic != topics.FEEDFORWARD:
                continue  # trials 1-2 ran before the interruption: in the other bag
            while pending and pending[0][0] <= stamp:
                writer.write(topics.TRIAL_EVENTS, *pending.pop(0))
            writer.write(conn.topic, stamp, raw)
        assert not pending
    run = read_bag(bag)
    assert run.resumed_after == 2
    assert run.completed == [3, 4, 5] and not run.incomplete
    assert run.aborted == [5] and run.trials[5].aborted_at == 60
    assert run.trials[3].aborted_at is None and run.trials[4].aborted_at is None
    assert run.trials[4].reruns == ["watchdog"] and run.trials[5].reruns == []
    for record in result.records[2:]:  # the retried attempt left the kept trial's samples alone
        np.testing.assert_array_equal(run.trials[record.trial].position, record.position)
    notes = "\n".join(run.notes)
    assert "resumed from its store after trial 2" in notes
    assert "trial 4 was aborted once and run again (watchdog" in notes
    assert "trial 5 was aborted by the error envelope at sample 60" in notes
    assert "trial 5 was aborted once" not in notes and "without a trial number" not in notes
    summary = run.summary()
    assert summary.extra["aborted_trials"] == [5] and summary.extra["resumed_after"] == 2
    assert summary.extra["sources"] == ["missing", "missing", "samples", "samples", "samples"]
    np.testing.assert_array_equal(summary.max_abs_error[2:], result.max_abs_errors[2:])


def test_analyze_cli_exports_and_figures(tmp_path: Path, mcap_bag: Path, config: Config,
                                         result: RunResult,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    out_json, out_csv, plot = tmp_path / "t.json", tmp_path / "t.csv", tmp_path / "f.png"
    code = exo_ilc(["analyze", str(mcap_bag), "--json", str(out_json), "--csv", str(out_csv),
                    "--plot", str(plot), "--trial", "2"])
    assert code == 0
    text = capsys.readouterr().out
    assert "Iterations to the bound" in text and "paper joint 1" in text
    document = json.loads(out_json.read_text())
    assert set(document) == {"config", "runs"}
    reference = RunSummary.from_result(result).to_json()
    (run,) = document["runs"]
    assert {k: run[k] for k in reference} == reference  # simulate's shape, plus bag info
    assert_same_table(RunSummary.from_json(run), RunSummary.from_result(result))
    rows = out_csv.read_text().splitlines()
    assert len(rows) == 1 + TRIALS and rows[0].startswith("bag,law,mass_uncertainty,trial")
    assert plot.stat().st_size > 10_000
    assert (tmp_path / "f_trial2.png").stat().st_size > 10_000


def test_figures_have_one_curve_per_run(config: Config, result: RunResult,
                                        mcap_bag: Path) -> None:
    names = config["joint_names"]
    other = RunSummary.from_result(result)
    other.mass_uncertainty = 0.15
    fig = convergence_figure([RunSummary.from_result(result), other], names)
    assert len(fig.axes) == config.joints
    for ax in fig.axes:
        assert len(ax.get_lines()) == 2 + 1  # two runs and the bound
        assert ax.get_yscale() == "log"
        bound = ax.get_lines()[-1]
        assert list(bound.get_ydata()) == [0.005, 0.005]
        assert len(ax.get_lines()[0].get_xdata()) == TRIALS
    trial = read_bag(mcap_bag).trials[2]
    fig = tracking_figure(trial, names)
    assert len(fig.axes) == 4 * config.joints
    assert [len(ax.get_lines()) for ax in fig.axes[:config.joints]] == [2] * config.joints


# --- over DDS: the real recorder against the real graph ------------------------------------

def _spin_until(session: Any, done: Any, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, session.processes.log_tail("ilc_supervisor")
        session.executor.spin_once(timeout_sec=0.05)


@pytest.mark.graph
def test_recorder_status_reports_received_then_filed(tmp_path: Path) -> None:
    """``trials_received``: the trial's end event is recorded; ``trials_filed``: its summary
    too and its file is finished (what the supervisor waits for before storing the trial)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.serialization import serialize_message

    from exo_ilc_ros.nodes.bag_recorder import BagRecorder

    def message(name: str, text: str, trial: int) -> bytes:
        item = DiagnosticStatus(name=name, message=text,
                                values=[KeyValue(key="trial", value=str(trial))])
        return bytes(serialize_message(DiagnosticArray(status=[item])))

    rclpy.init(args=["--ros-args", "-p", f"bag_path:={tmp_path / 'bag'}"])
    try:
        recorder = BagRecorder()
        try:
            def status() -> dict[str, str]:
                return dict(recorder.status_values())

            assert status()["trials_received"] == status()["trials_filed"] == "0"
            recorder.on_message(topics.TRIAL_EVENTS, message(topics.TRIAL_STATUS, "start", 1), 1)
            recorder.on_message(topics.TRIAL_EVENTS, message(topics.TRIAL_STATUS, "end", 1), 2)
            assert (status()["trials_received"], status()["trials_filed"]) == ("1", "0")
            recorder.on_message(topics.TRIAL_SUMMARY,
                                message(topics.SUMMARY_STATUS, "summary", 1), 3)
            assert (status()["trials_received"], status()["trials_filed"]) == ("1", "1")
            assert trials_filed(tmp_path / "bag") == 1
        finally:
            recorder.destroy_node()
        assert_bag_verifiable(tmp_path / "bag")
    finally:
        rclpy.try_shutdown()


def _wait_matched(*publishers: Any) -> None:
    """Until the recorder's subscriptions match ``publishers``, and the nodes' own start-up
    messages (parameter events) are in."""
    deadline = time.monotonic() + 10.0
    while any(p.get_subscription_count() < 1 for p in publishers):
        assert time.monotonic() < deadline, "recorder not matched"
        time.sleep(0.05)
    time.sleep(0.5)


@pytest.mark.graph
def test_recorder_takes_the_samples_at_trial_events_not_within_a_trial(tmp_path: Path) -> None:
    """Within a trial the recorder only looks at the trial events: the commands wait in DDS
    (not taken, not written) until the next event, then reach the bag in receive order before
    it; ``drain`` (after a stop) takes everything at once."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.duration import Duration
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from exo_ilc_ros.nodes.bag_recorder import BagRecorder
    from exo_ilc_ros.nodes.common import EVENTS_QOS

    rclpy.init(args=["--ros-args", "-p", f"bag_path:={tmp_path / 'bag'}"])
    try:
        recorder = BagRecorder()
        graph = Node("recorder_test_graph")
        commands = graph.create_publisher(Float64MultiArray, topics.EFFORT_COMMANDS, 10)
        events = graph.create_publisher(DiagnosticArray, topics.TRIAL_EVENTS, EVENTS_QOS)
        try:
            _wait_matched(commands, events)
            recorder.poll()  # the first poll takes everything and starts the period
            before = recorder.messages

            def publish(count: int) -> None:
                for i in range(count):
                    commands.publish(Float64MultiArray(data=[float(i), 0.0, 0.0]))
                assert commands.wait_for_all_acked(Duration(seconds=5))  # in the reader

            publish(5)
            assert recorder.poll() == 0 and recorder.messages == before  # in a trial: left
            start = DiagnosticStatus(name=topics.TRIAL_STATUS, message="start",
                                     values=[KeyValue(key="trial", value="1")])
            events.publish(DiagnosticArray(status=[start]))
            assert events.wait_for_all_acked(Duration(seconds=5))
            assert recorder.poll() == 6 and recorder.messages == before + 6
            assert recorder.started == 1
            publish(3)
            assert recorder.poll() == 0
            assert recorder.drain() == 3 and recorder.messages == before + 9
        finally:
            graph.destroy_node()
            recorder.destroy_node()
        counts = _bag_topic_counts(tmp_path / "bag")
        assert (counts[topics.EFFORT_COMMANDS], counts[topics.TRIAL_EVENTS]) == (8, 1)
    finally:
        rclpy.try_shutdown()


def test_recorder_beside_a_live_view_relays_within_a_trial_and_writes_at_events(
        tmp_path: Path) -> None:
    """With a relay, the recorder takes the samples every RELAY_PERIOD within a trial and
    hands them to the view at once, but writes them only at the next trial event (as without
    a view: the bag's writing stays out of the trial), before the event and in receive
    order; nothing is lost or written twice."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.duration import Duration
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from exo_ilc_ros.nodes.bag_recorder import BagRecorder
    from exo_ilc_ros.nodes.common import EVENTS_QOS
    from exo_ilc_ros.wire.relay import RelayReceiver

    view = RelayReceiver(tmp_path / "relay.sock")
    rclpy.init(args=["--ros-args", "-p", f"bag_path:={tmp_path / 'bag'}", "-p",
                     f"relay:={tmp_path / 'relay.sock'}", "-p", "relay_rate:=0.0"])
    try:
        recorder = BagRecorder()
        graph = Node("recorder_relay_test_graph")
        commands = graph.create_publisher(Float64MultiArray, topics.EFFORT_COMMANDS, 10)
        events = graph.create_publisher(DiagnosticArray, topics.TRIAL_EVENTS, EVENTS_QOS)
        shown: list[tuple[int, str, bytes]] = []
        try:
            _wait_matched(commands, events)
            recorder.poll()  # the first poll takes everything and starts the periods
            before = recorder.messages
            view.take()

            def publish(first: int, count: int) -> None:
                for i in range(first, first + count):
                    commands.publish(Float64MultiArray(data=[float(i), 0.0, 0.0]))
                assert commands.wait_for_all_acked(Duration(seconds=5))  # in the reader

            def relayed() -> list[float]:
                for _ in range(100):
                    got = view.take()
                    shown.extend(got)
                    if got:
                        break
                    time.sleep(0.01)
                return [read_float64_array(raw)[0] for _, topic, raw in shown
                        if topic == topics.EFFORT_COMMANDS]

            publish(0, 5)
            recorder.relay_due = 0.0  # the view's period is over
            assert recorder.poll() == 5 and recorder.messages == before  # taken, not written
            assert relayed() == [0.0, 1.0, 2.0, 3.0, 4.0]
            assert recorder.poll() == 0  # (within the view's period: nothing taken)
            publish(5, 2)
            start = DiagnosticStatus(name=topics.TRIAL_STATUS, message="start",
                                     values=[KeyValue(key="trial", value="1")])
            events.publish(DiagnosticArray(status=[start]))
            assert events.wait_for_all_acked(Duration(seconds=5))
            assert recorder.poll() == 3 and recorder.messages == before + 8
            assert relayed() == [float(i) for i in range(7)]
        finally:
            graph.destroy_node()
            recorder.destroy_node()
        counts = _bag_topic_counts(tmp_path / "bag")
        assert (counts[topics.EFFORT_COMMANDS], counts[topics.TRIAL_EVENTS]) == (7, 1)
        order = []
        for path in sorted((tmp_path / "bag").glob("*.mcap"),
                           key=lambda f: int(f.stem.rsplit("_", 1)[1])):
            with path.open("rb") as stream:
                order += [(channel.topic, read_float64_array(message.data)[0]
                           if channel.topic == topics.EFFORT_COMMANDS else None)
                          for _, channel, message in make_reader(stream).iter_messages(
                              topics=[topics.EFFORT_COMMANDS, topics.TRIAL_EVENTS],
                              log_time_order=False)]
        assert order == [*((topics.EFFORT_COMMANDS, float(i)) for i in range(7)),
                         (topics.TRIAL_EVENTS, None)]
    finally:
        rclpy.try_shutdown()
        view.close()


def _bag_topic_counts(path: Path) -> dict[str, int]:
    """Messages per topic in the bag's metadata.yaml."""
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {item["topic_metadata"]["name"]: int(item["message_count"])
            for item in info["topics_with_message_count"]}


@pytest.mark.graph
def test_recorder_sigkill_leaves_the_filed_trials(tmp_path: Path) -> None:
    """The real recorder on the real graph, killed with SIGKILL once it has filed trial 2 while
    the run goes on: its bag holds those trials, equal to the in-process run to 1e-12, and the
    live parameter change made before."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    from exo_ilc_ros.orchestration.graph import GraphSession
    from exo_ilc_ros.orchestration.recording import Recording

    # Enough trials that the run is still going when the recorder is killed: ten short ones
    # were over in 1.8 s once, before the parameter change was even answered.
    trials = 40
    config = load_config(overrides={**SHORT, "max_trials": trials, "wait_for_recorder": True})
    reference = run_trials(config)
    with Recording(config, tmp_path, "killed") as recording, \
            GraphSession(config, extra=[recording.spec]) as session:
        _spin_until(session, lambda: len(session.summaries) >= 1, 120)
        client = AsyncParameterClient(session.node, "ilc_supervisor")
        assert client.wait_for_services(timeout_sec=10.0)
        future = client.set_parameters([Parameter("error_bound", value=0.006)])
        _spin_until(session, future.done, 30)
        assert future.result().results[0].successful
        filed = max(2, len(session.summaries) + 1)  # a trial ended after the change
        _spin_until(session, lambda: trials_filed(recording.path) >= filed, 60)
        process = session.processes.processes.pop("bag_recorder")
        process.send_signal(signal.SIGKILL)
        assert process.wait(10) == -signal.SIGKILL
        _spin_until(session, lambda: session.finished, 120)

    run = read_bag(recording.path)
    assert_bag_verifiable(recording.path)  # every finished file: CRCs right and non-zero
    count = len(run.completed)
    assert 2 <= count < trials  # killed mid-run
    assert run.completed == list(range(1, count + 1))
    assert run.summary().extra["sources"] == ["samples"] * count
    np.testing.assert_allclose(run.summary().max_abs_error, reference.max_abs_errors[:count],
                               rtol=0, atol=1e-12)
    for record in reference.records[:count]:
        np.testing.assert_array_equal(run.trials[record.trial].position, record.position)
        np.testing.assert_array_equal(run.trials[record.trial].command, record.effort)
    (change,) = [c for c in run.parameter_changes if c.name == "error_bound"]
    assert change.node.endswith("ilc_supervisor") and change.value == 0.006
    assert 2 <= change.effective_trial <= count + 1


@pytest.mark.graph
def test_run_records_a_bag_that_analyses_to_its_table(tmp_path: Path) -> None:
    """`exo-ilc run` starts the recorder, stops it with SIGINT at the end; `exo-ilc analyze` of
    the bag prints/exports the run's own table (1e-12)."""
    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    run_json, bag_json = tmp_path / "run.json", tmp_path / "bag.json"
    proc = subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", "run", "--config",
                           str(config_file), "--trials", "3", "--quiet", "--json", str(run_json),
                           "--bag-dir", str(tmp_path / "bags")], capture_output=True, text=True,
                          timeout=150, stdin=subprocess.DEVNULL, check=False, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (bag,) = (tmp_path / "bags").iterdir()
    assert f"bag: {bag}" in proc.stderr
    # At start, for `exo-ilc param` from another terminal (docs/ros-graph.md), with a bag too.
    assert "graph on ROS_DOMAIN_ID=" in proc.stderr and f"recording to bag: {bag}" in proc.stderr
    assert exo_ilc(["analyze", str(bag), "--quiet", "--json", str(bag_json)]) == 0
    (graph,) = json.loads(run_json.read_text())["runs"]
    (recorded,) = json.loads(bag_json.read_text())["runs"]
    assert_same_table(RunSummary.from_json(recorded), RunSummary.from_json(graph))
    run = read_bag(bag)
    assert run.summary().extra["sources"] == ["samples"] * 3 and not run.notes
    assert not (bag / ".splits").exists()  # closed normally
    assert_bag_verifiable(bag)


def test_layouts_name_every_joint_and_known_topics(config: Config) -> None:
    layouts = Path(__file__).resolve().parents[1] / "config" / "layouts"
    foxglove = json.loads((layouts / "foxglove.json").read_text())
    plotjuggler = (layouts / "plotjuggler.xml").read_text()
    paths = [p["value"] for panel in foxglove["configById"].values()
             for p in panel.get("paths", [])]
    labels = [p["label"] for panel in foxglove["configById"].values()
              for p in panel.get("paths", [])]
    for name in config["joint_names"]:
        assert f"/joint_states/{name}/position" in plotjuggler
        assert name in labels
    scripts = {"/studio_script/tracking_error"}  # the layout's user script (test_live.py)
    for path in paths:
        assert path.split(".")[0] in {*topics.TYPES, *scripts}


def test_joint_states_decoded_row_wise_equal_rosbags() -> None:
    """The fast decoder against rosbags' own, with a message of another layout mixed in."""
    from exo_ilc_ros.bag import messages
    from exo_ilc_ros.wire.cdr import joint_states

    names = ["a", "bb", "ccc"]
    raws = [messages.joint_state(10**9 * k + 7, names, [k, 2.0, 3.0], [0.5, k, -1.0],
                                 [1.0, 2.0, k]) for k in range(5)]
    raws.insert(2, messages.joint_state(123, names, [9.0, 9.0, 9.0], [8.0, 8.0, 8.0], []))
    decoded = joint_states(raws, messages.typestore().deserialize_cdr)
    assert decoded.names == names
    for i, raw in enumerate(raws):
        msg = messages.typestore().deserialize_cdr(raw, topics.TYPES[topics.JOINT_STATES])
        assert decoded.stamps[i] == messages.time_ns(msg.header.stamp)
        np.testing.assert_array_equal(decoded.position[i], msg.position)
        np.testing.assert_array_equal(decoded.velocity[i], msg.velocity)
    assert np.isnan(decoded.effort[2]).all()
    np.testing.assert_array_equal(decoded.effort[3], [1.0, 2.0, 2.0])
