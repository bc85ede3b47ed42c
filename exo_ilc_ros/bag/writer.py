"""A rosbag2 bag written as a sequence of complete storage files, so a killed writer loses only
the file it was writing, and every file carries checksums a reader can verify.

An MCAP file's summary and index are written only when the file is finished: after SIGKILL a
file being written cannot be read. :class:`BagWriter` therefore writes each *split* (e.g. one
trial) as a file of its own in ``<bag>/.splits/``, and on :meth:`BagWriter.split` finishes it,
moves it to ``<bag>/<name>_<i>.mcap`` (rosbag2's naming for split bags) and rewrites
``metadata.yaml`` atomically to list every finished file. Readers (rosbags, ``ros2 bag``) see a
valid multi-file bag at every moment; an interrupted split stays in ``.splits/``.

MCAP files are written with ``mcap``'s writer: chunk, data-section and summary CRCs, so a
flipped byte is detected (:mod:`.integrity`); sqlite3 files with rosbags' public ``Writer``
(both behind :class:`.storage_files.StorageFile`).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

from .errors import BagWriteError
from .messages import typestore
from .metadata_yaml import INFO_KEY, MetadataYaml
from .storage_files import McapFile, Sqlite3File, StorageFile, Topic

SPLITS_DIR = ".splits"


@dataclass
class _FileInfo:
    path: str
    start: int
    end: int
    count: int


@dataclass
class _Split:
    file: StorageFile
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
        self._topics: dict[str, Topic] = {}
        self._files: list[_FileInfo] = []
        self._split: _Split | None = None
        self._bag_yaml = MetadataYaml(INFO_KEY)
        self._split_yaml = MetadataYaml(None)
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
        self._topics[topic] = Topic(topic, msgtype, tuple(qos))

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
        if isinstance(split.file, Sqlite3File):
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
        file: StorageFile
        if self.storage == "mcap":
            file = McapFile(staging / f"{name}.mcap")
        else:
            if (staging / name).exists():
                shutil.rmtree(staging / name)
            file = Sqlite3File(staging / name)
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
