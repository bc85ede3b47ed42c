"""Bags a reader can verify: every MCAP file the package writes carries non-zero chunk, data and
summary CRCs that ``mcap``'s own reader validates; a damaged byte is refused clearly; bags
written before (rosbags, no CRCs) still read; the QoS recorded per topic is what the graph's
publishers offer.

The oracle is the format's reference implementation (``mcap.reader`` with ``validate_crcs``,
``mcap.stream_reader``), plus the summary CRC recomputed here from the specification (the
Python reader does not check it).
"""

from __future__ import annotations

import io
import shutil
import zlib
from pathlib import Path

import numpy as np
import pytest
import yaml

from exo_ilc_ros.bag import BagReadError, BagWriter, read_bag, write_run
from exo_ilc_ros.bag.integrity import check_mcap, check_mcap_bytes
from exo_ilc_ros.cli.main import main as exo_ilc
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.session.result import RunResult
from exo_ilc_ros.wire import topics
from exo_ilc_ros.wire.qos import OFFERED

TRIALS = 3
SHORT = {"trajectory.duration": 1.0, "max_trials": TRIALS}
FOOTER = 1 + 8 + 8 + 8 + 4
"""The footer record's bytes: opcode, length, summary start, summary offset start, CRC."""


@pytest.fixture(scope="module")
def config() -> Config:
    return load_config(overrides=SHORT)


@pytest.fixture(scope="module")
def result(config: Config) -> RunResult:
    return run_trials(config, 0.10)


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory, config: Config, result: RunResult) -> Path:
    """One file per trial, as the recorder writes them."""
    return write_run(tmp_path_factory.mktemp("bags") / "run", config, result, split_every=1)


def assert_verifiable(file: Path) -> int:
    """``file`` passes mcap's reader with CRC validation (every message read), and every CRC
    it carries is non-zero and right; returns its message count."""
    from mcap.reader import make_reader
    from mcap.records import Chunk, DataEnd, Footer
    from mcap.stream_reader import StreamReader, breakup_chunk

    data = file.read_bytes()
    with open(file, "rb") as handle:
        reader = make_reader(handle, validate_crcs=True)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        count = sum(1 for _ in reader.iter_messages())
        metadata = [m.name for m in reader.iter_metadata()]
    assert count == summary.statistics.message_count > 0
    assert metadata == ["rosbag2"]
    assert summary.chunk_indexes and all(i.message_index_offsets for i in summary.chunk_indexes)
    chunks, footer, data_end = 0, None, None
    for record in StreamReader(io.BytesIO(data), validate_crcs=True, emit_chunks=True).records:
        if isinstance(record, Chunk):
            chunks += 1
            assert record.uncompressed_crc != 0
            breakup_chunk(record, validate_crc=True)
        elif isinstance(record, DataEnd):
            data_end = record
        elif isinstance(record, Footer):
            footer = record
    assert chunks == len(summary.chunk_indexes)
    assert data_end is not None and data_end.data_section_crc != 0
    assert footer is not None and footer.summary_crc != 0
    footer_at = len(data) - 8 - FOOTER
    assert zlib.crc32(data[footer.summary_start:footer_at + FOOTER - 4]) == footer.summary_crc
    check = check_mcap(file)
    assert check.intact and check.verifiable, check.problems
    return count


def assert_bag_verifiable(bag: Path) -> None:
    """Every file of ``bag`` is verifiable and together they hold every message listed."""
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    files = info["relative_file_paths"]
    assert files and sorted(files) == sorted(p.name for p in bag.glob("*.mcap"))
    assert sum(assert_verifiable(bag / name) for name in files) == info["message_count"]


def flip(file: Path, offset: int) -> None:
    data = bytearray(file.read_bytes())
    data[offset] ^= 0xFF
    file.write_bytes(bytes(data))


def test_run_writer_bags_are_verifiable(bag: Path) -> None:
    assert len(list(bag.glob("*.mcap"))) == TRIALS + 1  # a file per trial, the last event
    assert_bag_verifiable(bag)


def test_simulate_bag_is_verifiable_and_reads_back(tmp_path: Path, config: Config) -> None:
    """``exo-ilc simulate --bag DIR`` (one file, the graph's topics)."""
    short = tmp_path / "short.yaml"
    short.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    out = tmp_path / "bags"
    assert exo_ilc(["simulate", "--config", str(short), "--trials", "2", "--quiet",
                    "--bag", str(out)]) == 0
    (written,) = out.iterdir()
    assert_bag_verifiable(written)
    assert read_bag(written).completed == [1, 2]


def test_large_batched_file_is_verifiable(tmp_path: Path) -> None:
    """Several chunks (over 1 MiB each), written in batches as the recorder does."""
    rng = np.random.default_rng(5)
    with BagWriter(tmp_path / "big") as writer:
        for topic in (topics.JOINT_STATES, topics.CLOCK):
            writer.add_topic(topic, topics.TYPES[topic])
        for start in range(0, 9000, 500):
            writer.write_many([(start + i, topics.JOINT_STATES if i % 3 else topics.CLOCK,
                                rng.bytes(400)) for i in range(500)])
    (file,) = (tmp_path / "big").glob("*.mcap")
    assert check_mcap(file).chunks >= 3
    assert assert_verifiable(file) == 9000


def _messages(bag: Path) -> list[tuple[str, int, int, bytes]]:
    """Every message of ``bag``'s MCAP files (topic, log time, publish time, bytes), in order,
    through ``mcap``'s reader with CRC validation."""
    from mcap.reader import make_reader

    out = []
    for file in sorted(bag.glob("*.mcap")):
        with open(file, "rb") as handle:
            out += [(channel.topic, m.log_time, m.publish_time, m.data) for _, channel, m in
                    make_reader(handle, validate_crcs=True).iter_messages(log_time_order=False)]
    return out


def test_chunks_are_compressed_and_lose_nothing(tmp_path: Path, bag: Path, config: Config,
                                                result: RunResult,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Every chunk is zstd-compressed (its messages in a third of their bytes or less) and the
    bag holds exactly the messages of the same run written uncompressed (the writer as it was),
    in half the bytes or less (here, where each file's copy of the config weighs; a 150-trial
    graph run took ~105 MiB uncompressed)."""
    from mcap.reader import make_reader

    from exo_ilc_ros.bag import storage_files

    stored = raw = 0
    for file in bag.glob("*.mcap"):
        with open(file, "rb") as handle:
            chunks = make_reader(handle).get_summary().chunk_indexes
        assert chunks and {c.compression for c in chunks} == {"zstd"}, file.name
        stored += sum(c.compressed_size for c in chunks)
        raw += sum(c.uncompressed_size for c in chunks)
    assert stored * 3 < raw
    monkeypatch.setattr(storage_files, "CHUNK_COMPRESSION", "NONE")
    plain = write_run(tmp_path / "plain", config, result, split_every=1)
    messages = _messages(bag)
    assert len(messages) > 900 and messages == _messages(plain)

    def size(path: Path) -> int:
        return sum(f.stat().st_size for f in path.glob("*.mcap"))

    assert size(bag) * 2 < size(plain)


def test_every_single_byte_flip_is_detected(bag: Path) -> None:
    """Flip each byte of a finished file in turn: the check finds every one (each byte is under
    a CRC, a length the CRCs cover, or the magic), and never raises."""
    file = bag / f"{bag.name}_{TRIALS}.mcap"  # the last file: the ``finished`` event
    original = file.read_bytes()
    assert len(original) < 50_000  # its metadata record carries the run's config too
    missed = []
    data = bytearray(original)
    for offset in range(len(original)):
        data[offset] ^= 0xFF
        check = check_mcap_bytes(data)
        data[offset] ^= 0xFF
        if check.intact and check.verifiable:
            missed.append(offset)
    assert not missed, f"undetected flips at bytes {missed[:10]}"
    assert check_mcap_bytes(data).intact


def test_flipped_chunk_byte_is_refused_clearly(tmp_path: Path, bag: Path, result: RunResult,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A byte flipped inside a chunk's messages: mcap's reader, the check, ``read_bag`` and
    ``exo-ilc analyze`` all refuse it; the error names the file and says what failed, with no
    traceback; ``--skip-damaged`` analyses the other files."""
    from mcap.reader import make_reader
    from mcap.stream_reader import CRCValidationError

    copy = tmp_path / "damaged"
    shutil.copytree(bag, copy)
    file = copy / f"{bag.name}_1.mcap"
    with open(file, "rb") as handle:
        (chunk,) = make_reader(handle).get_summary().chunk_indexes
    flip(file, chunk.chunk_start_offset + chunk.chunk_length // 2)
    with open(file, "rb") as handle, pytest.raises(CRCValidationError):
        list(make_reader(handle, validate_crcs=True).iter_messages())
    check = check_mcap(file)
    assert not check.intact
    assert check.problems[0] == (f"chunk at byte {chunk.chunk_start_offset} "
                                 f"({chunk.uncompressed_size} bytes) fails its CRC: messages "
                                 "in it are damaged")
    assert check.problems[1].startswith("data section (bytes 0-")  # the data CRC covers it too
    with pytest.raises(BagReadError, match=f"{file.name}: is corrupt.*fails its CRC"):
        read_bag(copy)
    capsys.readouterr()
    assert exo_ilc(["analyze", str(copy), "--quiet"]) != 0
    err = capsys.readouterr().err
    assert "is corrupt" in err and file.name in err and "Traceback" not in err
    assert "--skip-damaged" in err
    # The rest of the bag is still there: trial 2's file left out, with a note.
    run = read_bag(copy, skip_damaged=True)
    assert run.completed == [1, 3]
    assert run.summary().extra["sources"] == ["samples", "missing", "samples"]
    np.testing.assert_array_equal(run.summary().max_abs_error[[0, 2]],
                                  result.max_abs_errors[[0, 2]])
    assert any(note.startswith(f"{file.name} left out: it is corrupt") for note in run.notes)
    assert exo_ilc(["analyze", str(copy), "--quiet", "--skip-damaged"]) == 0
    assert f"note: {file.name} left out" in capsys.readouterr().out


def test_damaged_summary_is_refused(tmp_path: Path, bag: Path) -> None:
    """The summary (channels, index, statistics) has a CRC of its own."""
    copy = tmp_path / "summary"
    shutil.copytree(bag, copy)
    file = copy / f"{bag.name}_0.mcap"
    data = file.read_bytes()
    footer_at = len(data) - 8 - FOOTER
    summary_start = int.from_bytes(data[footer_at + 9:footer_at + 17], "little")
    flip(file, (summary_start + footer_at) // 2)
    with pytest.raises(BagReadError, match=r"summary .* fails its CRC"):
        read_bag(copy)


def test_bag_written_before_reads_with_a_note(tmp_path: Path, bag: Path, config: Config,
                                              result: RunResult) -> None:
    """A bag as exo_ilc_ros wrote them before (rosbags' MCAP writer: every CRC 0) reads to the
    same table, with a note that its damage could not have been detected."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    from exo_ilc_ros.bag.messages import typestore
    from exo_ilc_ros.bag.provenance import provenance_data

    old = tmp_path / "old"
    writer = Writer(old, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
    for key, value in provenance_data(config.with_mass_uncertainty(0.10),
                                      recorded_by="exo-ilc simulate").items():
        writer.set_custom_data(key, value)
    with AnyReader([bag]) as reader, writer:
        connections = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=typestore(),
                                                      offered_qos_profiles=c.ext.offered_qos_profiles)
                       for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            writer.write(connections[conn.topic], stamp, raw)
    (file,) = old.glob("*.mcap")
    check = check_mcap(file)
    assert check.intact and not check.verifiable and check.chunk_crcs == 0
    run = read_bag(old)
    np.testing.assert_array_equal(run.summary().max_abs_error, result.max_abs_errors)
    assert any("carry no chunk CRCs" in note for note in run.notes)
    # Damage such a file's structure can still show: a clear refusal, not a traceback.
    from mcap.reader import make_reader

    with open(file, "rb") as handle:
        chunk = make_reader(handle).get_summary().chunk_indexes[0]
    first_record = chunk.chunk_start_offset + 9 + 40 + len(chunk.compression)
    flip(file, first_record + 5)  # a high byte of the first record's length
    with pytest.raises(BagReadError, match=r"is damaged \(in the chunk at byte"):
        read_bag(old)


def test_qos_recorded_as_published(bag: Path) -> None:
    """metadata.yaml and every MCAP channel record each topic's offered QoS: events, summaries
    and diagnostics transient local (with their depths), the feed-forward transient local depth
    1, the samples volatile; rosbags parses the channels' text to the same profiles."""
    from mcap.reader import make_reader
    from rosbags.rosbag2.metadata import parse_qos

    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    recorded = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
                for t in info["topics_with_message_count"]}
    assert set(recorded) == set(topics.BAG_TYPES)  # every topic, with or without messages
    for topic, profiles in recorded.items():
        assert [(p["durability"], p["depth"]) for p in profiles] == list(OFFERED[topic])
        assert all(p["reliability"] == "reliable" and p["history"] == "keep_last"
                   for p in profiles)
    assert recorded[topics.TRIAL_EVENTS][0]["durability"] == "transient_local"
    assert recorded[topics.TRIAL_SUMMARY][0]["depth"] == 1000
    assert OFFERED[topics.DIAGNOSTICS][0] == ("transient_local", 10)
    for file in bag.glob("*.mcap"):
        with open(file, "rb") as handle:
            channels = make_reader(handle).get_summary().channels
        for channel in channels.values():
            parsed = parse_qos(channel.metadata["offered_qos_profiles"])
            assert [(q.durability.name.lower(), q.depth) for q in parsed] == \
                list(OFFERED[channel.topic])
            assert channel.metadata["topic_type_hash"].startswith("RIHS01_")


REQUIRED = (topics.JOINT_STATES, topics.CLOCK, topics.EFFORT_COMMANDS, topics.FEEDFORWARD,
            topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY, topics.DIAGNOSTICS, topics.PARAMETER_EVENTS)
"""The topics whose offered QoS the recorder test compares with the bag's metadata."""


@pytest.mark.graph
def test_recorder_bag_is_verifiable_and_offers_the_graphs_qos(tmp_path: Path) -> None:
    """The real recorder on the real graph: every file it writes passes mcap's reader with CRC
    validation, and the QoS its metadata records per topic is what the running graph's
    publishers offer (reliability and durability; DDS discovery does not carry the depth, so
    ``ros2 bag record`` itself records 0 and ``ros2 bag play`` uses its default depth)."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    from exo_ilc_ros.orchestration.graph import GraphSession
    from exo_ilc_ros.orchestration.recording import Recording

    config = load_config(overrides={**SHORT, "max_trials": 2, "wait_for_recorder": True})
    offered: dict[str, set[str]] = {}
    with Recording(config, tmp_path) as recording, \
            GraphSession(config, nodes=recording.graph_nodes()) as session:
        session.spin_until(lambda: len(session.summaries) >= 1, timeout=120.0)

        def look() -> bool:  # the monitor's graph view can lag an endpoint: look again
            for topic in OFFERED:
                for info in session.node.get_publishers_info_by_topic(topic):
                    profile = info.qos_profile
                    assert profile.reliability == ReliabilityPolicy.RELIABLE, (topic, info)
                    kind = ("transient_local" if profile.durability ==
                            DurabilityPolicy.TRANSIENT_LOCAL else "volatile")
                    offered.setdefault(topic, set()).add(kind)
            return all(t in offered for t in REQUIRED)

        session.spin_until(look, timeout=10.0)
        session.spin_until(lambda: session.finished, timeout=120.0)
    for topic in REQUIRED:
        assert offered[topic] == {kind for kind, _ in OFFERED[topic]}, topic
    assert_bag_verifiable(recording.path)
    info = yaml.safe_load((recording.path / "metadata.yaml").read_text())
    for entry in info["rosbag2_bagfile_information"]["topics_with_message_count"]:
        metadata = entry["topic_metadata"]
        name = metadata["name"]  # the view's topics: written by the recorder, as ROS offers
        expected = {kind for kind, _ in OFFERED[name]} if name in topics.VIEW_TYPES \
            else offered[name]
        assert {p["durability"] for p in metadata["offered_qos_profiles"]} == expected
        assert all(p["reliability"] == "reliable" for p in metadata["offered_qos_profiles"])
    assert read_bag(recording.path).completed == [1, 2]


def test_mcap_walk_reads_what_rosbags_reads(tmp_path: Path, bag: Path) -> None:
    """read_bag's MCAP reader against rosbags' AnyReader (the reference it replaced): the same
    messages per topic, in the same order, with the same log times; and the same from copies
    of a file with zstd and lz4 chunks (``ros2 bag record``'s default is zstd)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer
    from rosbags.highlevel import AnyReader

    from exo_ilc_ros.bag.mcap_messages import read_mcap_topics

    wanted = list(topics.BAG_TYPES)
    walked: dict[str, list[tuple[int, bytes]]] = {}
    for file in sorted(bag.glob("*.mcap")):
        found = read_mcap_topics(file, wanted)
        assert found.check.intact
        for topic, log in found.log.items():
            walked.setdefault(topic, []).extend(zip(log, found.data[topic], strict=True))
    reference: dict[str, list[tuple[int, bytes]]] = {}
    with AnyReader([bag]) as reader:
        for conn, stamp, raw in reader.messages():
            reference.setdefault(conn.topic, []).append((stamp, bytes(raw)))
    # per trial: 101 samples, commands and /tf, 11 /clock (every 10th sample, the first and
    # the last), feed-forward, start, end, summary, metrics, the controller's loaded and done;
    # then finished; and the two URDFs at the start
    per_trial = 3 * 101 + 11 + 7
    assert walked == reference and sum(map(len, walked.values())) == TRIALS * per_trial + 3

    plain = bag / f"{bag.name}_1.mcap"
    for compression in (CompressionType.ZSTD, CompressionType.LZ4):
        copy = tmp_path / f"{compression.name}.mcap"
        with open(plain, "rb") as source, open(copy, "wb") as target:
            reader = make_reader(source)
            summary = reader.get_summary()
            assert summary is not None
            writer = Writer(target, compression=compression, chunk_size=50_000)
            writer.start("ros2", "test")
            for schema in summary.schemas.values():
                assert writer.register_schema(schema.name, schema.encoding,
                                              schema.data) == schema.id
            for channel in summary.channels.values():
                assert writer.register_channel(channel.topic, channel.message_encoding,
                                               channel.schema_id, channel.metadata) == channel.id
            for _, channel, message in reader.iter_messages(log_time_order=False):
                writer.add_message(channel.id, message.log_time, message.data,
                                   message.publish_time)
            writer.finish()
        found, original = read_mcap_topics(copy, wanted), read_mcap_topics(plain, wanted)
        assert found.check.intact and found.check.chunks > 1
        assert found.log == original.log and found.data == original.data
        assert found.types == original.types


def test_another_publishers_junk_in_a_bag_is_left_out_with_a_note() -> None:
    """The recorder keeps whatever was published on a topic, a foreign publisher's junk too
    (the nodes refused it live): the reader drops what is not CDR of the topic's type, with a
    note, and keeps the rest in order (decoded, or raw after the encapsulation check)."""
    from exo_ilc_ros.bag import messages
    from exo_ilc_ros.bag.storage import Stream as _Stream
    from exo_ilc_ros.bag.storage import _keep_decodable

    good = messages.joint_state(5, ["a"], [0.1], [0.2], [0.0])
    rng = np.random.default_rng(3)
    junk = [rng.bytes(40), b"\x00\x01\x00\x00" + rng.bytes(3), b"\x00"]
    stream = _Stream(log=[1, 2, 3, 4, 5], msgs=[good, junk[0], good, junk[1], junk[2]])
    notes: list[str] = []
    decode = messages.typestore().deserialize_cdr
    _keep_decodable(topics.JOINT_STATES, stream, decode, topics.TYPES[topics.JOINT_STATES],
                    True, notes)
    assert stream.log == [1, 3] and [m.position.tolist() for m in stream.msgs] == [[0.1]] * 2
    assert notes and notes[0].startswith(f"3 message(s) on {topics.JOINT_STATES}")
    raw = _Stream(log=[1, 2, 3], msgs=[good, junk[0], good])
    _keep_decodable(topics.JOINT_STATES, raw, decode, topics.TYPES[topics.JOINT_STATES],
                    False, notes)
    assert raw.log == [1, 3] and raw.msgs == [good, good]
