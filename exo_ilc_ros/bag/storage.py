"""A bag's storage, read: its ``metadata.yaml`` and the messages of the topics asked for, in
log-time order (MCAP through :mod:`.mcap_messages` after its CRCs are checked, sqlite3 through
rosbags' ``AnyReader``). What the messages mean is :mod:`.reader`'s."""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..wire import topics
from . import messages
from .errors import BagReadError
from .mcap_messages import McapReadError, read_mcap_topics
from .provenance import read_provenance

CDR_HEADERS = (b"\x00\x00", b"\x00\x01")
"""The encapsulations a rosbag2 CDR message starts with (big- and little-endian plain CDR)."""


def safe_load_yaml(text: str) -> Any:
    """``yaml.safe_load``, parsed by libyaml when PyYAML has it (a 150-trial bag's
    metadata.yaml took most of its analysis with the pure-Python parser; the same resolvers and
    constructor, so the same values); a document libyaml refuses is parsed again by PyYAML's own
    parser, so an error says what PyYAML says."""
    try:
        return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError:
        return yaml.safe_load(text)


def read_metadata(path: Path) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` of the bag at ``path``."""
    meta = path / "metadata.yaml"
    try:
        document = safe_load_yaml(meta.read_text())
    except OSError as exc:
        raise BagReadError(path, f"no readable metadata.yaml ({exc.strerror}); is it a "
                           "rosbag2 bag directory?") from None
    except yaml.YAMLError as exc:
        raise BagReadError(meta, f"invalid YAML: {exc}") from None
    if not isinstance(document, dict) or "rosbag2_bagfile_information" not in document:
        raise BagReadError(meta, "no rosbag2_bagfile_information")
    info = document["rosbag2_bagfile_information"]
    return info if isinstance(info, dict) else {}


def trials_filed(path: Path | str) -> int:
    """Trials the recorder has finished files for, from ``metadata.yaml`` (rewritten after each
    trial); 0 while there is no readable metadata yet (a live or just-started recording)."""
    try:
        info = read_metadata(Path(path))
    except BagReadError:
        return 0
    return read_provenance(info.get("custom_data")).trials_completed or 0


@dataclass
class Stream:
    """Messages of one topic: log times, and the decoded messages (or the raw ones, for the
    topics decoded lazily)."""

    log: list[int] = field(default_factory=list)
    msgs: list[Any] = field(default_factory=list)


def read_topics(path: Path, info: dict[str, Any], skip_damaged: bool, wanted: Sequence[str],
                 raw_topics: Iterable[str]
                 ) -> tuple[dict[str, Stream], Callable[[bytes, str], Any], list[str]]:
    """The ``wanted`` topics' messages in log-time order (deserialised, or raw for
    ``raw_topics``), the deserialiser, and notes. MCAP files are read by
    :mod:`.mcap_messages` after their CRCs are checked; other storages by rosbags."""
    if info.get("storage_identifier") == "mcap":
        return _read_mcap(path, info, wanted, set(raw_topics), skip_damaged)
    return (*_read_with_rosbags(path, wanted, raw_topics), [])


def _read_mcap(path: Path, info: dict[str, Any], wanted: Sequence[str], keep_raw: set[str],
               skip_damaged: bool
               ) -> tuple[dict[str, Stream], Callable[[bytes, str], Any], list[str]]:
    """Every file of the bag in turn: refused by name if a checksum fails (or left out with a
    note, ``skip_damaged``); a note for files without CRCs (written before exo_ilc_ros wrote
    bags with ``mcap``: damage to them cannot be seen). Each topic's messages are then put in
    log-time order (stable), as rosbags does."""
    streams = {t: Stream() for t in wanted}
    types: dict[str, str] = {}
    unchecked: list[str] = []
    notes: list[str] = []
    for name in info.get("relative_file_paths") or []:
        file = path / str(name)
        if not file.is_file():
            raise BagReadError(file, "is listed in metadata.yaml but missing")
        try:
            found = read_mcap_topics(file, wanted)
        except OSError as exc:
            raise BagReadError(file, f"cannot be read ({exc.strerror or exc})") from None
        except McapReadError as exc:
            raise BagReadError(file, f"is damaged ({exc}); it carries no CRCs that would say "
                               "where") from None
        check = found.check
        if not check.intact:
            damage = "is corrupt, its checksums do not match: " + "; ".join(check.problems)
            if not skip_damaged:
                raise BagReadError(file, f"{damage}. The bag's other files are checked on "
                                   "their own: `exo-ilc analyze --skip-damaged` (read_bag(..., "
                                   "skip_damaged=True)) analyses them without this one.")
            notes.append(f"{file.name} left out: it {damage}")
            continue
        if check.chunks and check.chunk_crcs < check.chunks:
            unchecked.append(file.name)
        for topic, msgtype in found.types.items():
            expected = topics.TYPES.get(topic)
            if topic in streams and expected and msgtype != expected:
                raise BagReadError(file, f"topic {topic} has type {msgtype}, expected "
                                   f"{expected}")
            types.setdefault(topic, msgtype)
        for topic, log in found.log.items():
            streams[topic].log.extend(log)
            streams[topic].msgs.extend(found.data[topic])
    deserialize = messages.typestore().deserialize_cdr
    for topic, stream in streams.items():
        times = np.asarray(stream.log, dtype=np.int64)
        if times.size > 1 and np.any(np.diff(times) < 0):
            order = np.argsort(times, kind="stable")
            stream.log = [stream.log[i] for i in order]
            stream.msgs = [stream.msgs[i] for i in order]
        _keep_decodable(topic, stream, deserialize, types.get(topic, ""),
                        topic not in keep_raw, notes)
    if unchecked:
        notes.append(f"{len(unchecked)} of the bag's files ({unchecked[0]}"
                     f"{', ...' if len(unchecked) > 1 else ''}) carry no chunk CRCs (written "
                     "before exo_ilc_ros wrote bags with mcap): damage to them could not be "
                     "detected")
    return streams, deserialize, notes


def _keep_decodable(topic: str, stream: Stream, deserialize: Callable[[bytes, str], Any],
                    msgtype: str, decode: bool, notes: list[str]) -> None:
    """Drop (with a note) the messages of ``stream`` that are not CDR of ``msgtype``: the
    recorder keeps whatever was published, a foreign publisher's junk included (the nodes
    refused it live); ``decode``: replace the others by their deserialised messages, else
    keep them raw after a check of their encapsulation only."""
    kept_log, kept = [], []
    for log, raw in zip(stream.log, stream.msgs, strict=True):
        if bytes(raw[:2]) not in CDR_HEADERS or len(raw) < 4:
            continue
        if decode:
            try:
                raw = deserialize(raw, msgtype)
            except Exception:  # any decoding failure: junk, dropped
                continue
        kept_log.append(log)
        kept.append(raw)
    dropped = len(stream.msgs) - len(kept)
    if dropped:
        notes.append(f"{dropped} message(s) on {topic} are not {msgtype or 'CDR'} and were "
                     "left out (another publisher's junk: the nodes refused it live)")
    stream.log, stream.msgs = kept_log, kept


def _read_with_rosbags(path: Path, wanted: Sequence[str], raw_topics: Iterable[str]
                       ) -> tuple[dict[str, Stream], Callable[[bytes, str], Any]]:
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.rosbag2 import ReaderError

    streams = {t: Stream() for t in wanted}
    keep_raw = set(raw_topics)
    try:
        with AnyReader([path], default_typestore=messages.typestore()) as reader:
            connections = [c for c in reader.connections if c.topic in streams]
            for conn in connections:
                expected = topics.TYPES.get(conn.topic)
                if expected and conn.msgtype != expected:
                    raise BagReadError(path, f"topic {conn.topic} has type {conn.msgtype}, "
                                       f"expected {expected}")
            deserialize = reader.typestore.deserialize_cdr
            for conn, log_time, raw in reader.messages(connections=connections):
                stream = streams[conn.topic]
                stream.log.append(log_time)
                stream.msgs.append(raw if conn.topic in keep_raw
                                   else deserialize(raw, conn.msgtype))
    except (AnyReaderError, ReaderError) as exc:
        raise BagReadError(path, f"rosbags cannot read it: {exc}") from None
    return streams, deserialize


def frame_id(raw: bytes, decode: Callable[[bytes, str], Any]) -> str:
    """header.frame_id of a CDR message without decoding the rest (a feed-forward profile is
    thousands of points)."""
    if len(raw) >= 16 and raw[:2] == b"\x00\x01":  # little-endian CDR: stamp, then the string
        (length,) = struct.unpack_from("<I", raw, 12)
        if 0 < length <= len(raw) - 16:
            return raw[16:16 + length - 1].decode(errors="replace")
    return str(decode(raw, topics.TYPES[topics.FEEDFORWARD]).header.frame_id)


def statuses(stream: Stream, name: str) -> Iterator[tuple[int, int, Any]]:
    for log, msg in zip(stream.log, stream.msgs, strict=True):
        for status in msg.status:
            if status.name == name:
                yield messages.time_ns(msg.header.stamp), log, status
