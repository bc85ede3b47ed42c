"""A rosbag2 bag written as a sequence of complete storage files, so a killed writer loses only
the file it was writing.

rosbags' :class:`~rosbags.rosbag2.Writer` keeps a 1 MiB chunk and the whole index in memory and
writes the MCAP summary and ``metadata.yaml`` only on ``close()``: after SIGKILL nothing of it can
be read. :class:`BagWriter` therefore writes each *split* (e.g. one trial) with its own rosbags
``Writer`` in ``<bag>/.splits/``, and on :meth:`BagWriter.split` closes it, moves the finished
file to ``<bag>/<name>_<i>.mcap`` (rosbag2's naming for split bags) and rewrites
``metadata.yaml`` atomically to list every finished file. Readers (rosbags, ``ros2 bag``) see a
valid multi-file bag at every moment; an interrupted split stays in ``.splits/``.
"""

from __future__ import annotations

import os
import shutil
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import yaml

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


def _qos_text(version: int, qos: Sequence[Any]) -> str:
    """The offered-QoS YAML rosbags' ``Writer.add_connection`` stores with a connection."""
    from io import StringIO

    from rosbags.rosbag2.metadata import dump_qos_v8, dump_qos_v9
    from ruamel.yaml import YAML

    dumped = (dump_qos_v9 if version >= 9 else dump_qos_v8)(list(qos))
    if isinstance(dumped, str):
        return dumped
    stream = StringIO()
    yaml_ = YAML(typ="safe")
    yaml_.default_flow_style = False
    yaml_.dump(dumped, stream)
    return stream.getvalue().strip()


_MESSAGE_HEADER = struct.Struct("<BQHIQQ")
"""An MCAP Message record up to its data: opcode 0x05, record length, channel id, sequence
(0, as rosbags writes it), log time, publish time."""
_CHUNK_LIMIT = 2**20
"""rosbags closes a chunk once it holds more than this many bytes (``McapWriter.write``)."""


def _mcap_chunk(chunk: Any) -> bool:
    """Whether ``chunk`` is rosbags' pending MCAP chunk as :func:`_pack_mcap_messages` knows
    it (a rosbags release that changed it falls back to one call per message)."""
    return chunk is not None and all(hasattr(chunk, a) for a in
                                      ("bio", "msgs", "message_start_time", "message_end_time"))


def _pack_mcap_messages(storage: Any, chunk: Any, batch: Sequence[tuple[int, str, bytes]],
                        connections: Mapping[str, Any]) -> None:
    """Append ``batch`` to rosbags' open MCAP chunk exactly as its ``McapWriter.write`` would
    one message at a time (records, chunk index, times, channel statistics), closing the chunk
    where it would."""
    pack = _MESSAGE_HEADER.pack
    stats = storage.channel_stats
    i = 0
    while i < len(batch):
        bio = chunk.bio
        offset = bio.tell()
        index = chunk.msgs
        parts = []
        start, end = chunk.message_start_time, chunk.message_end_time
        while i < len(batch) and offset <= _CHUNK_LIMIT:
            timestamp, topic, data = batch[i]
            cid = connections[topic].id
            record = pack(0x05, 22 + len(data), cid, 0, timestamp, timestamp)
            index[cid].append((timestamp, offset))
            parts.append(record)
            parts.append(data)
            offset += 31 + len(data)
            stats[cid] += 1
            start = min(start, timestamp)
            end = max(end, timestamp)
            i += 1
        bio.write(b"".join(parts))
        chunk.message_start_time, chunk.message_end_time = start, end
        storage.message_start_time = min(storage.message_start_time, start)
        storage.message_end_time = max(storage.message_end_time, end)
        if bio.tell() > _CHUNK_LIMIT:
            storage.close_chunk()
            chunk = storage.chunk


@dataclass
class _Topic:
    name: str
    msgtype: str
    qos: Sequence[Any]
    count: int = 0
    _metadata: dict[str, Any] | None = None

    def metadata(self) -> dict[str, Any]:
        """Its ``topic_metadata`` entry (computed once: the hash and QoS do not change)."""
        if self._metadata is None:
            from rosbags.rosbag2.metadata import dump_qos_v9

            self._metadata = {"name": self.name, "type": self.msgtype,
                              "serialization_format": "cdr",
                              "offered_qos_profiles": dump_qos_v9(list(self.qos)),
                              "type_description_hash": typestore().hash_rihs01(self.msgtype)}
        return self._metadata


@dataclass
class _FileInfo:
    path: str
    start: int
    end: int
    count: int


@dataclass
class _Split:
    writer: Any
    staging: Path
    connections: dict[str, Any] = field(default_factory=dict)
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
        from rosbags.rosbag2 import StoragePlugin

        self.path = Path(path)
        plugins = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
        if storage not in plugins:
            raise BagWriteError(self.path, f"unknown storage {storage!r}; use mcap or sqlite3")
        self.storage = storage
        self._plugin = plugins[storage]
        self.custom_data: dict[str, str] = dict(custom_data or {})
        self._topics: dict[str, _Topic] = {}
        self._templates: dict[str, tuple[Any, str]] = {}
        """Per topic: its connection in the first split and its QoS YAML (see _connect)."""
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
        its publisher offers (rosbags ``Qos`` tuples; ``ros2 bag play`` replays with them)."""
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

    def write(self, topic: str, timestamp: int, data: bytes | memoryview) -> None:
        """Store one message (CDR bytes) of a declared topic at ``timestamp`` ns."""
        if not self._opened or self._closed:
            raise BagWriteError(self.path, "write on a bag that is not open")
        split = self._split or self._open_split()
        connection = split.connections.get(topic)
        if connection is None:
            declared = self._topics.get(topic)
            if declared is None:
                raise BagWriteError(self.path, f"write to undeclared topic {topic}")
            connection = self._connect(split, declared)
        split.writer.write(connection, timestamp, data)
        split.counts[topic] = split.counts.get(topic, 0) + 1
        split.start = min(split.start, timestamp)
        split.end = max(split.end, timestamp)

    def write_many(self, messages: Iterable[tuple[int, str, bytes]]) -> int:
        """Store ``(timestamp ns, topic, CDR bytes)`` messages in order (an
        :class:`~exo_ilc_ros.nodes.common.Inbox`'s batch); returns how many.

        The same file as :meth:`write` one by one, at a fraction of the cost per message: for
        MCAP the message records of the batch are packed here and appended to rosbags' open
        chunk (what its ``McapWriter.write`` does per message, byte for byte; tested), the
        recorder's main cost next to the control loop. Other storages write one by one.
        """
        batch = messages if isinstance(messages, list) else list(messages)
        if not batch:
            return 0
        if not self._opened or self._closed:
            raise BagWriteError(self.path, "write on a bag that is not open")
        split = self._split or self._open_split()
        connections = split.connections
        done = 0
        for i, (_, topic, _) in enumerate(batch):
            if topic not in connections:  # connected where write() would (rosbags writes the
                self._write_batch(split, batch[done:i])  # channel into the chunk)
                declared = self._topics.get(topic)
                if declared is None:
                    raise BagWriteError(self.path, f"write to undeclared topic {topic}")
                self._connect(split, declared)
                done = i
        self._write_batch(split, batch[done:])
        counts = split.counts
        for _, topic, _ in batch:
            counts[topic] = counts.get(topic, 0) + 1
        first = min(timestamp for timestamp, _, _ in batch)
        last = max(timestamp for timestamp, _, _ in batch)
        split.start = min(split.start, first)
        split.end = max(split.end, last)
        return len(batch)

    def _write_batch(self, split: _Split, batch: Sequence[tuple[int, str, bytes]]) -> None:
        """Messages of topics connected in ``split``: packed for MCAP, else one by one."""
        storage = split.writer.storage
        chunk = getattr(storage, "chunk", None)
        if not _mcap_chunk(chunk):
            for timestamp, topic, data in batch:
                split.writer.write(split.connections[topic], timestamp, data)
        elif batch:
            _pack_mcap_messages(storage, chunk, batch, split.connections)

    def split(self) -> Path | None:
        """Finish the file being written (if it holds any message) and list it in
        ``metadata.yaml``; returns the finished file."""
        split, self._split = self._split, None
        if split is None:
            return None
        self._finish_storage(split)
        produced = [p for p in split.staging.iterdir() if p.name != "metadata.yaml"]
        if len(produced) != 1:
            raise BagWriteError(split.staging, f"expected one storage file, found {produced}")
        target = self.path / produced[0].name
        os.replace(produced[0], target)
        shutil.rmtree(split.staging, ignore_errors=True)
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
        from rosbags.rosbag2 import Writer

        name = f"{self.path.name}_{len(self._files)}"
        staging = self.path / SPLITS_DIR / name
        if staging.exists():
            shutil.rmtree(staging)
        writer = Writer(staging, version=Writer.VERSION_LATEST, storage_plugin=self._plugin)
        writer.open()
        self._split = _Split(writer, staging)
        return self._split

    def _finish_storage(self, split: _Split) -> None:
        """Write the split's index and footer. What rosbags' ``Writer.close`` does, minus its
        two ruamel dumps of the metadata (~0.1 s per split, a stall the recorder cannot
        afford); the storage gets the split's metadata from libyaml instead."""
        writer = split.writer
        storage, writer.storage = writer.storage, None
        info = self._metadata([_FileInfo(f"{split.staging.name}.{self._suffix}", split.start,
                                         split.end, sum(split.counts.values()))],
                              {t: split.counts.get(t, 0) for t in self._topics}, {})
        storage.close(writer.version, self._split_yaml.dump(info).strip())

    def _connect(self, split: _Split, topic: _Topic) -> Any:
        """Add ``topic``'s connection to the split being written.

        The first split goes through rosbags' ``Writer.add_connection``; later splits reuse
        what it computed (message definition, hash, the QoS YAML) and register the same
        connection with the storage directly: ``add_connection`` regenerates the definition
        and dumps the QoS with ruamel every time, ~1.5 ms per topic and split, which the
        recorder paid at the start of every trial, next to the control loop.
        """
        writer = split.writer
        template = self._templates.get(topic.name)
        if template is None or template[0].ext.offered_qos_profiles != list(topic.qos):
            connection = writer.add_connection(topic.name, topic.msgtype,
                                               typestore=typestore(),
                                               offered_qos_profiles=list(topic.qos))
            self._templates[topic.name] = (connection, _qos_text(writer.version, topic.qos))
        else:
            connection = template[0]._replace(id=len(writer.connections) + 1, owner=writer)
            if topic.msgtype not in writer.added_types:
                writer.storage.add_msgtype(connection)
                writer.added_types.add(topic.msgtype)
            writer.storage.add_connection(connection, template[1])
            writer.connections.append(connection)
            writer.counts[connection.id] = 0
        split.connections[topic.name] = connection
        return connection

    @property
    def _suffix(self) -> str:
        return "mcap" if self.storage == "mcap" else "db3"

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
                {"topic_metadata": t.metadata(), "message_count": counts[t.name]}
                for t in self._topics.values() if counts.get(t.name)],
            "compression_format": "",
            "compression_mode": "",
            "files": [{"path": f.path, "starting_time": {"nanoseconds_since_epoch": f.start},
                       "duration": {"nanoseconds": max(0, f.end - f.start)},
                       "message_count": f.count} for f in files],
            "custom_data": dict(custom_data) or None,
            "ros_distro": "jazzy",
        }
        return info
