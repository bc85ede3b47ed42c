"""A rosbag2 bag written as a sequence of complete storage files, so a killed writer loses only
the file it was writing, and every file carries checksums a reader can verify.

An MCAP file's summary and index are written only when the file is finished: after SIGKILL a
file being written cannot be read. :class:`BagWriter` therefore writes each *split* (e.g. one
trial) as a file of its own in ``<bag>/.splits/``, and on :meth:`BagWriter.split` finishes it,
moves it to ``<bag>/<name>_<i>.mcap`` (rosbag2's naming for split bags) and rewrites
``metadata.yaml`` atomically to list every finished file. Readers (rosbags, ``ros2 bag``) see a
valid multi-file bag at every moment; an interrupted split stays in ``.splits/``.

MCAP files are written with ``mcap``'s writer (:class:`_McapFile`): chunk, data-section and
summary CRCs, so a flipped byte is detected (:mod:`.integrity`); sqlite3 files with rosbags'
public ``Writer``.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml

from .. import __version__
from .errors import BagWriteError
from .messages import typestore

SPLITS_DIR = ".splits"
_Dumper: Any = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
"""libyaml's dumper when PyYAML has it: metadata.yaml is rewritten after every split."""


INFO_KEY = "rosbag2_bagfile_information"


def _dump(data: Any) -> str:
    return str(yaml.dump(data, Dumper=_Dumper, sort_keys=False, width=10**9))


class _MetadataYaml:
    """The YAML of a metadata dict (under ``wrapper``), the same text as one ``yaml.dump``
    but made of pieces dumped once: every entry of a list (files, topics) and of
    ``custom_data``, in its place. A split then dumps only what changed (times and counts)
    instead of the whole, ever-growing file list: the dump was the largest part of a split,
    which the supervisor waits for between trials."""

    def __init__(self, wrapper: str | None) -> None:
        self.wrapper = wrapper
        self._pieces: dict[tuple[str, str], str] = {}

    def dump(self, info: Mapping[str, Any]) -> str:
        """``yaml.dump({wrapper: info})`` (or of ``info`` without a wrapper)."""
        used: dict[tuple[str, str], str] = {}

        def piece(key: str, value: Any, skip: int) -> str:
            """``{key: value}`` in its place, without its first ``skip`` lines."""
            cache_key = (key, repr(value))
            text = used.get(cache_key) or self._pieces.get(cache_key)
            if text is None:
                data = {key: value} if self.wrapper is None else {self.wrapper: {key: value}}
                lines = _dump(data).splitlines(keepends=True)
                text = "".join(lines[skip + (self.wrapper is not None):])
            used[cache_key] = text
            return text

        indent = "" if self.wrapper is None else "  "
        parts = [] if self.wrapper is None else [f"{self.wrapper}:\n"]
        for key, value in info.items():
            if _counts(value):  # times and counts change with every split: formatted here
                parts.append(f"{indent}{key}: {value}\n" if isinstance(value, int) else
                             f"{indent}{key}:\n" + "".join(f"{indent}  {k}: {v}\n"
                                                             for k, v in value.items()))
            elif isinstance(value, list) and value:
                parts.append(piece(key, [], 0).replace(" []", ""))
                for item in value:
                    last = list(item)[-1] if isinstance(item, dict) and len(item) > 1 else None
                    if last is not None and _counts(item[last]):  # a topic's message count
                        parts.append(piece(key, [{k: v for k, v in item.items() if k != last}],
                                           1) + f"{indent}  {last}: {item[last]}\n")
                    else:
                        parts.append(piece(key, [item], 1))
            elif isinstance(value, dict) and value and key == "custom_data":
                parts.append(piece(key, {}, 0).replace(" {}", ""))
                parts.extend(piece(key, {k: v}, 1) for k, v in value.items())
            else:
                parts.append(piece(key, value, 0))
        self._pieces = used
        return "".join(parts)


def _counts(value: Any) -> bool:
    """An int, or a dict of ints under plain keys (``{"nanoseconds": 5}``)."""
    if isinstance(value, dict):
        return bool(value) and all(isinstance(v, int) and not isinstance(v, bool) and
                                   k.isidentifier() for k, v in value.items())
    return isinstance(value, int) and not isinstance(value, bool)


CHUNK_SIZE = 2**20
"""An MCAP chunk is closed once it holds more than this many bytes (1 MiB, as before)."""


def qos_yaml(profiles: Sequence[dict[str, Any]]) -> str:
    """The ``offered_qos_profiles`` text of an MCAP channel, as rosbag2 Jazzy writes it
    (``serialize_rclcpp_qos_vector``: the version-9 profiles as a YAML block sequence, keys in
    ``rmw_qos_profile_t``'s order)."""
    if not profiles:
        return ""
    return str(yaml.dump(list(profiles), Dumper=_Dumper, sort_keys=False,
                         default_flow_style=False, width=10**9)).strip()


class _McapFile:
    """One storage file written with ``mcap``'s :class:`~mcap.writer.Writer` (the format's
    reference implementation): chunked, uncompressed as before, with chunk, data-section and
    summary CRCs, message and chunk indexes, statistics, and rosbag2's ``ros2`` profile (one
    ``ros2msg`` schema per type; channels carry ``offered_qos_profiles`` and
    ``topic_type_hash``; a ``rosbag2`` metadata record holds the file's metadata)."""

    def __init__(self, path: Path) -> None:
        from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer


        self.path = path
        self._handle = open(path, "wb")  # noqa: SIM115  (closed by finish)
        self._writer = Writer(self._handle, chunk_size=CHUNK_SIZE,
                              compression=CompressionType.NONE, index_types=IndexType.ALL,
                              enable_crcs=True, enable_data_crcs=True)
        self._writer.start(profile="ros2",
                           library=f"exo_ilc_ros-{__version__}; {LIBRARY_IDENTIFIER}")
        self._schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        """Topic -> channel id, for the topics that have a message in this file."""

    def connect(self, topic: _Topic) -> int:
        """Register ``topic``'s channel (and its type's schema, once per file)."""
        schema = self._schemas.get(topic.msgtype)
        if schema is None:
            schema = self._writer.register_schema(topic.msgtype, "ros2msg",
                                                  topic.definition().encode())
            self._schemas[topic.msgtype] = schema
        channel = self._writer.register_channel(topic.name, "cdr", schema,
                                                topic.channel_metadata())
        self.channels[topic.name] = channel
        return channel

    def write(self, channel: int, timestamp: int, data: bytes | memoryview,
              publish_time: int | None = None) -> None:
        """One message: log time ``timestamp`` (ns), publish time ``publish_time`` (default:
        the log time)."""
        self._writer.add_message(channel, timestamp, data,
                                 timestamp if publish_time is None else publish_time)

    def write_batch(self, channels: Mapping[str, int],
                    batch: Sequence[tuple[int, str, bytes] | tuple[int, str, bytes, int]]
                    ) -> None:
        """Messages of topics connected in this file, in order; a 4th item is the publish
        time (else the log time)."""
        add = self._writer.add_message
        for item in batch:
            add(channels[item[1]], item[0], item[2], item[3] if len(item) > 3 else item[0])

    def finish(self, metadata: str) -> None:
        """The ``rosbag2`` metadata record, the summary (indexes, statistics, CRC) and the
        footer; closes the file."""
        try:
            self._writer.flush()  # the last chunk first: the metadata follows the messages
            self._writer.add_metadata("rosbag2", {"serialized_metadata": metadata})
            self._writer.finish()
        finally:
            self._handle.close()


class _Sqlite3File:
    """One sqlite3 storage file, written through rosbags' public ``Writer`` API in a staging
    directory of its own (sqlite3 has no checksums; rosbags writes what rosbag2 does)."""

    def __init__(self, staging: Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.staging = staging
        self._writer = Writer(staging, version=Writer.VERSION_LATEST,
                              storage_plugin=StoragePlugin.SQLITE3)
        self._writer.open()
        self._connections: dict[int, Any] = {}
        self.channels: dict[str, int] = {}

    @property
    def path(self) -> Path:
        return self.staging / f"{self.staging.name}.db3"

    def connect(self, topic: _Topic) -> int:
        connection = self._writer.add_connection(topic.name, topic.msgtype,
                                                 typestore=typestore(),
                                                 offered_qos_profiles=list(topic.qos))
        self._connections[connection.id] = connection
        self.channels[topic.name] = connection.id
        return int(connection.id)

    def write(self, channel: int, timestamp: int, data: bytes | memoryview,
              publish_time: int | None = None) -> None:
        del publish_time  # sqlite3 storage has one time per message
        self._writer.write(self._connections[channel], timestamp, data)

    def write_batch(self, channels: Mapping[str, int],
                    batch: Sequence[tuple[int, str, bytes] | tuple[int, str, bytes, int]]
                    ) -> None:
        for item in batch:
            self.write(channels[item[1]], item[0], item[2])

    def finish(self, metadata: str) -> None:
        """Close the database (rosbags also writes a ``metadata.yaml`` in the staging
        directory, which the bag's own replaces)."""
        del metadata
        self._writer.close()


@dataclass
class _Topic:
    name: str
    msgtype: str
    qos: Sequence[Any]
    count: int = 0
    _metadata: dict[str, Any] | None = None
    _definition: str | None = None
    _channel_metadata: dict[str, str] | None = None

    def metadata(self) -> dict[str, Any]:
        """Its ``topic_metadata`` entry (computed once: the hash and QoS do not change)."""
        if self._metadata is None:
            from rosbags.rosbag2.metadata import dump_qos_v9

            self._metadata = {"name": self.name, "type": self.msgtype,
                              "serialization_format": "cdr",
                              "offered_qos_profiles": dump_qos_v9(list(self.qos)),
                              "type_description_hash": typestore().hash_rihs01(self.msgtype)}
        return self._metadata

    def definition(self) -> str:
        """The full ``ros2msg`` definition of its type (the MCAP schema's data)."""
        if self._definition is None:
            self._definition = str(typestore().generate_msgdef(self.msgtype, ros_version=2)[0])
        return self._definition

    def channel_metadata(self) -> dict[str, str]:
        """The MCAP channel's metadata, as rosbag2's MCAP storage writes it."""
        if self._channel_metadata is None:
            info = self.metadata()
            self._channel_metadata = {
                "offered_qos_profiles": qos_yaml(info["offered_qos_profiles"]),
                "topic_type_hash": info["type_description_hash"]}
        return self._channel_metadata


@dataclass
class _FileInfo:
    path: str
    start: int
    end: int
    count: int


@dataclass
class _Split:
    file: _McapFile | _Sqlite3File
    start: int = 2**63 - 1
    end: int = 0
    counts: dict[str, int] = field(default_factory=dict)


class BagWriter:
    """Writes a rosbag2 bag (MCAP or sqlite3 storage) in splits; use as a context manager.

    ``add_topic`` declares a topic once; ``write`` stores CDR bytes as given (no
    re-serialisation); ``split`` finishes the current file; ``close`` finishes the bag.
    """

    def __init__(self, path: Path | str, *, storage: str = "mcap",
                 custom_data: Mapping[str, str] | None = None) -> None:
        self.path = Path(path)
        if storage not in ("mcap", "sqlite3"):
            raise BagWriteError(self.path, f"unknown storage {storage!r}; use mcap or sqlite3")
        self.storage = storage
        self.custom_data: dict[str, str] = dict(custom_data or {})
        self._topics: dict[str, _Topic] = {}
        self._files: list[_FileInfo] = []
        self._split: _Split | None = None
        self._bag_yaml = _MetadataYaml(INFO_KEY)
        self._split_yaml = _MetadataYaml(None)
        self._opened = False
        self._closed = False

    # -- lifecycle -------------------------------------------------------------------------
    def open(self) -> None:
        """Create the bag directory (it must not exist) and write an empty ``metadata.yaml``."""
        if self.path.exists():
            raise BagWriteError(self.path, "exists already; a bag is never overwritten")
        try:
            (self.path / SPLITS_DIR).mkdir(parents=True)
        except OSError as exc:
            raise BagWriteError(self.path, f"cannot create: {exc.strerror}") from None
        self._opened = True
        self._write_metadata()

    def close(self) -> None:
        """Finish the current split and the bag (idempotent)."""
        if self._closed or not self._opened:
            return
        self.split()
        self._closed = True
        self._write_metadata()
        shutil.rmtree(self.path / SPLITS_DIR, ignore_errors=True)

    def __enter__(self) -> BagWriter:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- content ---------------------------------------------------------------------------
    def add_topic(self, topic: str, msgtype: str, qos: Sequence[Any] = ()) -> None:
        """Declare ``topic`` of ``msgtype`` (e.g. ``sensor_msgs/msg/JointState``) with the QoS
        its publishers offer (rosbags ``Qos`` tuples, one per distinct publisher profile;
        ``ros2 bag play`` offers them again)."""
        known = self._topics.get(topic)
        if known is not None:
            if known.msgtype != msgtype:
                raise BagWriteError(self.path, f"topic {topic} added as {known.msgtype}, "
                                    f"then as {msgtype}")
            return
        if msgtype not in typestore().types:
            raise BagWriteError(self.path, f"topic {topic}: unknown message type {msgtype}")
        self._topics[topic] = _Topic(topic, msgtype, tuple(qos))

    def set_custom_data(self, key: str, value: str) -> None:
        """Set a ``custom_data`` entry (written with the next split and at close)."""
        if not isinstance(value, str):
            raise BagWriteError(self.path, f"custom_data {key}: value must be a string, "
                                f"got {type(value).__name__}")
        self.custom_data[key] = value

    def write(self, topic: str, timestamp: int, data: bytes | memoryview,
              publish_time: int | None = None) -> None:
        """Store one message (CDR bytes) of a declared topic at log time ``timestamp`` ns
        (MCAP: publish time ``publish_time``, default the log time)."""
        if not self._opened or self._closed:
            raise BagWriteError(self.path, "write on a bag that is not open")
        split = self._split or self._open_split()
        channel = split.file.channels.get(topic)
        if channel is None:
            channel = self._connect(split, topic)
        split.file.write(channel, timestamp, data, publish_time)
        split.counts[topic] = split.counts.get(topic, 0) + 1
        split.start = min(split.start, timestamp)
        split.end = max(split.end, timestamp)

    def write_many(self, messages: Iterable[tuple[int, str, bytes] |
                                        tuple[int, str, bytes, int]]) -> int:
        """Store ``(log time ns, topic, CDR bytes[, publish time ns])`` messages in order (an
        :class:`~exo_ilc_ros.nodes.common.Inbox`'s batch); returns how many.

        The same file as :meth:`write` one by one (tested), with the per-message bookkeeping
        (counts, times) done once per batch: the recorder's main cost next to the control loop.
        """
        batch = messages if isinstance(messages, list) else list(messages)
        if not batch:
            return 0
        if not self._opened or self._closed:
            raise BagWriteError(self.path, "write on a bag that is not open")
        split = self._split or self._open_split()
        channels = split.file.channels
        done = 0
        for i, item in enumerate(batch):
            topic = item[1]
            if topic not in channels:  # its channel goes where write() would put it
                split.file.write_batch(channels, batch[done:i])
                self._connect(split, topic)
                done = i
        split.file.write_batch(channels, batch[done:])
        counts = split.counts
        for item in batch:
            counts[item[1]] = counts.get(item[1], 0) + 1
        first = min(item[0] for item in batch)
        last = max(item[0] for item in batch)
        split.start = min(split.start, first)
        split.end = max(split.end, last)
        return len(batch)

    def split(self) -> Path | None:
        """Finish the file being written (if it holds any message) and list it in
        ``metadata.yaml``; returns the finished file."""
        split, self._split = self._split, None
        if split is None:
            return None
        produced = split.file.path
        info = self._metadata([_FileInfo(produced.name, split.start, split.end,
                                         sum(split.counts.values()))],
                              {t: split.counts.get(t, 0) for t in self._topics},
                              self.custom_data)  # each file carries the run's config too
        split.file.finish(self._split_yaml.dump(info).strip())
        target = self.path / produced.name
        os.replace(produced, target)
        if isinstance(split.file, _Sqlite3File):
            shutil.rmtree(split.file.staging, ignore_errors=True)
        for topic, count in split.counts.items():
            self._topics[topic].count += count
        self._files.append(_FileInfo(target.name, split.start, split.end,
                                     sum(split.counts.values())))
        self._write_metadata()
        return target

    @property
    def files(self) -> list[Path]:
        """The finished storage files, in order."""
        return [self.path / f.path for f in self._files]

    # -- internals -------------------------------------------------------------------------
    def _open_split(self) -> _Split:
        """Start file ``<name>_<i>`` in ``.splits/`` (moved into the bag when finished)."""
        name = f"{self.path.name}_{len(self._files)}"
        staging = self.path / SPLITS_DIR
        file: _McapFile | _Sqlite3File
        if self.storage == "mcap":
            file = _McapFile(staging / f"{name}.mcap")
        else:
            if (staging / name).exists():
                shutil.rmtree(staging / name)
            file = _Sqlite3File(staging / name)
        self._split = _Split(file)
        return self._split

    def _connect(self, split: _Split, topic: str) -> int:
        """The channel of declared ``topic`` in the split being written."""
        declared = self._topics.get(topic)
        if declared is None:
            raise BagWriteError(self.path, f"write to undeclared topic {topic}")
        return split.file.connect(declared)

    def _write_metadata(self) -> None:
        info = self._metadata(self._files, {t.name: t.count for t in self._topics.values()},
                              self.custom_data)
        text = self._bag_yaml.dump(info)
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(text)
        os.replace(tmp, self.path / "metadata.yaml")

    def _metadata(self, files: Sequence[_FileInfo], counts: Mapping[str, int],
                  custom_data: Mapping[str, str]) -> dict[str, Any]:
        """``rosbag2_bagfile_information`` (version 9) of ``files``."""
        start = min((f.start for f in files), default=0)
        end = max((f.end for f in files), default=0)
        info: dict[str, Any] = {
            "version": 9,
            "storage_identifier": self.storage,
            "relative_file_paths": [f.path for f in files],
            "duration": {"nanoseconds": max(0, end - start)},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": sum(f.count for f in files),
            "topics_with_message_count": [
                {"topic_metadata": t.metadata(), "message_count": counts.get(t.name, 0)}
                for t in self._topics.values()],  # every recorded topic, as ros2 bag record
            "compression_format": "",
            "compression_mode": "",
            "files": [{"path": f.path, "starting_time": {"nanoseconds_since_epoch": f.start},
                       "duration": {"nanoseconds": max(0, f.end - f.start)},
                       "message_count": f.count} for f in files],
            "custom_data": dict(custom_data) or None,
            "ros_distro": "jazzy",
        }
        return info
