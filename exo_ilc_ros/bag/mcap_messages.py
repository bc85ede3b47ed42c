"""The messages of chosen topics of an MCAP file, read after its checksums are verified.

:func:`read_mcap_topics` checks the file (:func:`.integrity.check_mcap_bytes`), then walks its
records once: schemas and channels (top level or inside chunks, as the specification allows)
name each channel's topic and type, and the Message records of the wanted topics are kept as
``(log time, CDR bytes)`` in file order. Chunks may be uncompressed, zstd or lz4 (what rosbag2's
MCAP storage writes).

Why not rosbags' reader, which :func:`~.reader.read_bag` used before: it parses every channel's
``offered_qos_profiles`` YAML with ruamel in every file (~3-5 ms each: 150 one-trial files took
seconds), which the reader could only avoid by patching rosbags' module; and it checks only the
chunk CRCs. ``mcap``'s own reader builds an object per record (2 s for the same 150-trial bag).
This walk is tested to give exactly what rosbags' ``AnyReader`` gives (``test_bag_integrity``);
rosbags still reads sqlite3 bags and deserialises every message (its typestore).
"""

from __future__ import annotations

import mmap
import struct
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path

from .integrity import McapCheck, check_mcap_bytes, decompress_chunk

OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_DATA_END = 0x03, 0x04, 0x05, 0x06, 0x0F
_RECORD = struct.Struct("<BQ")
_MESSAGE = struct.Struct("<HIQQ")
"""A Message record up to its data: channel id, sequence, log time, publish time."""
_U16, _U32 = struct.Struct("<H"), struct.Struct("<I")


@dataclass
class McapTopics:
    """What :func:`read_mcap_topics` found in one file."""

    check: McapCheck
    types: dict[str, str] = field(default_factory=dict)
    """Every topic with a channel in the file -> its type (the schema's name)."""
    log: dict[str, list[int]] = field(default_factory=dict)
    """Per wanted topic: the log times (ns) of its messages, in file order."""
    data: dict[str, list[bytes]] = field(default_factory=dict)
    """Per wanted topic: the CDR bytes of its messages, in file order."""


class McapReadError(ValueError):
    """A file whose records cannot be walked (damaged, and without CRCs that would say so)."""


def read_mcap_topics(path: Path | str, wanted: Collection[str]) -> McapTopics:
    """Check ``path``'s CRCs, then take the messages of the ``wanted`` topics (skipped, with
    the check's problems in ``check``, when the file is damaged)."""
    path = Path(path)
    error = ""
    with open(path, "rb") as handle:
        if handle.seek(0, 2) == 0:
            return McapTopics(check_mcap_bytes(b"", path))
        with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as data:
            view = memoryview(data)
            try:
                out = McapTopics(check_mcap_bytes(view, path))
                if out.check.intact:
                    _Walk(out, set(wanted)).records(view, 8, None)
            except McapReadError as exc:
                error = str(exc)  # raised below, once no view of the map is left to close
            finally:
                view.release()
    if error:
        raise McapReadError(error)
    return out


class _Walk:
    """One pass over a file's records, filling a :class:`McapTopics`."""

    def __init__(self, out: McapTopics, wanted: set[str]) -> None:
        self.out = out
        self.wanted = wanted
        self.schemas: dict[int, str] = {}
        self.channels: dict[int, str | None] = {}
        """Channel id -> its topic if wanted, else None."""

    def records(self, view: memoryview, offset: int, end: int | None) -> None:
        """The records from ``offset``: to the Data End record (top level, ``end`` None) or to
        ``end`` (a chunk's records)."""
        unpack_record, unpack_message = _RECORD.unpack_from, _MESSAGE.unpack_from
        log, data = self.out.log, self.out.data
        channels = self.channels
        limit = len(view) if end is None else end
        try:
            while offset < limit:
                opcode, length = unpack_record(view, offset)
                body = offset + 9
                offset = body + length
                if offset > limit:
                    raise McapReadError(f"record at byte {body - 9} runs past byte {limit}")
                if opcode == OP_MESSAGE:
                    channel, _, log_time, _ = unpack_message(view, body)
                    topic = channels.get(channel)
                    if topic is not None:
                        log[topic].append(log_time)
                        data[topic].append(bytes(view[body + 22:offset]))
                elif opcode == OP_CHANNEL:
                    self._channel(view, body)
                elif opcode == OP_SCHEMA:
                    (schema,) = _U16.unpack_from(view, body)
                    self.schemas[schema] = _string(view, body + 2)[0]
                elif opcode == OP_CHUNK and end is None:
                    records, _, _, _ = decompress_chunk(view, body, length)
                    try:
                        self.records(memoryview(records), 0, len(records))
                    except McapReadError as exc:
                        raise McapReadError(f"in the chunk at byte {body - 9}: {exc}") from None
                elif opcode == OP_DATA_END and end is None:
                    return
        except McapReadError:
            raise
        except (struct.error, UnicodeDecodeError, ValueError) as exc:
            raise McapReadError(f"damaged record near byte {offset}: {exc}") from None
        if end is None:
            raise McapReadError("no Data End record")

    def _channel(self, view: memoryview, body: int) -> None:
        channel, schema = struct.unpack_from("<HH", view, body)
        topic, _ = _string(view, body + 4)
        self.out.types[topic] = self.schemas.get(schema, "")
        if topic in self.wanted:
            self.channels[channel] = topic
            self.out.log.setdefault(topic, [])
            self.out.data.setdefault(topic, [])
        else:
            self.channels[channel] = None


def _string(view: memoryview, at: int) -> tuple[str, int]:
    """A length-prefixed UTF-8 string at ``at`` and the offset after it."""
    (length,) = _U32.unpack_from(view, at)
    end = at + 4 + length
    if end > len(view):
        raise McapReadError(f"string at byte {at} runs past the record")
    return str(view[at + 4:end], "utf-8"), end
