"""Checking an MCAP file's checksums before trusting what it holds.

MCAP carries three kinds of CRC32 (the format's specification, "Chunk", "Data End" and
"Footer" records): each chunk's over its uncompressed records, the data section's over every
byte from the magic to the Data End record, and the summary's over the summary section and the
footer up to the CRC itself. A stored 0 means "not computed" (rosbags wrote only zeros; bags
written by exo_ilc_ros before the ``mcap`` writer have none).

:func:`check_mcap` walks the file's top-level records (opcode and length only; chunks are
decompressed to check their CRC) and recomputes every CRC that is present: one pass of
``zlib.crc32`` over the file, ~0.1 s for a 150-trial bag, so :func:`~.reader.read_bag` checks
every file before it reads one. ``mcap``'s own reader checks chunk and data CRCs too, but builds
an object per record (seconds for the same bag) and does not check the summary's.
"""

from __future__ import annotations

import mmap
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

MAGIC = b"\x89MCAP0\r\n"
"""The 8 bytes an MCAP file starts and ends with."""

OP_CHUNK, OP_DATA_END, OP_FOOTER = 0x06, 0x0F, 0x02
_RECORD = struct.Struct("<BQ")
"""Opcode and length of a record."""
_CHUNK_HEAD = struct.Struct("<QQQIl")
"""A chunk's message start and end time, uncompressed size and CRC, then the length of its
compression string (read as signed so that a damaged length cannot pass for huge)."""
_FOOTER = struct.Struct("<BQQQI")
"""The footer record: opcode, length (20), summary start, summary offset start, summary CRC."""


@dataclass
class McapCheck:
    """What :func:`check_mcap` found in one file."""

    path: Path
    problems: list[str] = field(default_factory=list)
    """Each checksum that does not match, or a structure that cannot be read (empty: intact)."""
    chunks: int = 0
    chunk_crcs: int = 0
    """Chunks that carry a CRC (the others were written without one)."""
    data_crc: int = 0
    summary_crc: int = 0

    @property
    def intact(self) -> bool:
        """No checksum failed and the structure is sound."""
        return not self.problems

    @property
    def verifiable(self) -> bool:
        """Every chunk, the data section and the summary carry a CRC (and the file has a
        chunk): corruption anywhere would have been found."""
        return (self.chunks > 0 and self.chunk_crcs == self.chunks and self.data_crc != 0
                and self.summary_crc != 0)


def _decompress(data: memoryview, compression: str, size: int) -> bytes | memoryview:
    """A chunk's records: as stored, or decompressed by ``mcap``'s own reader code (zstd,
    lz4: what rosbag2's MCAP storage may write)."""
    if compression == "":
        return data
    if compression not in ("zstd", "lz4"):
        raise ValueError(f"unknown chunk compression {compression!r}")
    from mcap.records import Chunk
    from mcap.stream_reader import get_chunk_data_stream

    stream, length = get_chunk_data_stream(Chunk(
        compression=compression, data=bytes(data), message_start_time=0, message_end_time=0,
        uncompressed_crc=0, uncompressed_size=size))
    return stream.read(length)


def check_mcap(path: Path | str) -> McapCheck:
    """Recompute every CRC the MCAP file at ``path`` carries and compare; the problems name
    the record and its byte offset."""
    path = Path(path)
    with open(path, "rb") as handle:
        size = handle.seek(0, 2)
        if size == 0:
            return check_mcap_bytes(b"", path)
        with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as data:
            view = memoryview(data)
            try:
                return check_mcap_bytes(view, path)
            finally:
                view.release()


def check_mcap_bytes(data: bytes | memoryview, path: Path | str = "<bytes>") -> McapCheck:
    """:func:`check_mcap` of a file's contents."""
    check = McapCheck(Path(path))
    view = memoryview(data)
    if len(view) < 2 * len(MAGIC) + _FOOTER.size:
        check.problems.append(f"{len(view)} bytes: too short for an MCAP file (truncated?)")
        return check
    _check(view, len(view), check)
    return check


def _check(view: memoryview, size: int, check: McapCheck) -> None:
    problems = check.problems
    if view[:8] != MAGIC:
        problems.append("does not start with the MCAP magic")
        return
    if view[size - 8:] != MAGIC:
        problems.append("does not end with the MCAP magic (truncated, or never finished)")
        return
    footer_at = size - 8 - _FOOTER.size
    opcode, length, summary_start, _, summary_crc = _FOOTER.unpack_from(view, footer_at)
    if opcode != OP_FOOTER or length != 20:
        problems.append(f"no footer record at byte {footer_at}")
        return
    check.summary_crc = summary_crc
    if summary_crc:
        begin = summary_start or footer_at
        if not 8 <= begin <= footer_at:
            problems.append(f"footer points at a summary at byte {begin}, outside the file")
        elif zlib.crc32(view[begin:footer_at + _FOOTER.size - 4]) != summary_crc:
            problems.append(f"summary (bytes {begin}-{footer_at + _FOOTER.size}) fails its "
                            "CRC: the index, channels or statistics are damaged")
    offset = 8
    end = summary_start or footer_at
    while True:
        if offset + _RECORD.size > end:
            problems.append(f"no Data End record before byte {end} (truncated or damaged)")
            return
        opcode, length = _RECORD.unpack_from(view, offset)
        body = offset + _RECORD.size
        if body + length > end:
            problems.append(f"record (opcode 0x{opcode:02x}) at byte {offset} claims "
                            f"{length} bytes, past the data section's end at byte {end}")
            return
        if opcode == OP_CHUNK:
            _check_chunk(view, offset, body, length, check)
        elif opcode == OP_DATA_END:
            if length < 4:
                problems.append(f"Data End record at byte {offset} is {length} bytes long")
                return
            (data_crc,) = struct.unpack_from("<I", view, body)
            check.data_crc = data_crc
            if data_crc and zlib.crc32(view[:offset]) != data_crc:
                problems.append(f"data section (bytes 0-{offset}) fails its CRC")
            return
        offset = body + length


def decompress_chunk(view: memoryview, body: int, length: int
                     ) -> tuple[bytes | memoryview, int, int, str]:
    """The chunk record whose body is ``view[body:body + length]``: its records (decompressed),
    uncompressed size, CRC and compression. Raises ``ValueError`` where it is damaged."""
    if length < _CHUNK_HEAD.size:
        raise ValueError(f"{length} bytes long")
    _, _, uncompressed_size, crc, name_length = _CHUNK_HEAD.unpack_from(view, body)
    at = body + _CHUNK_HEAD.size
    if not 0 <= name_length <= length - _CHUNK_HEAD.size - 8:
        raise ValueError("damaged header")
    compression = str(view[at:at + name_length], "utf-8", "replace")
    at += name_length
    (records_length,) = struct.unpack_from("<Q", view, at)
    at += 8
    if at + records_length != body + length:
        raise ValueError("its records do not fill it (damaged header)")
    records = _decompress(view[at:at + records_length], compression, uncompressed_size)
    return records, uncompressed_size, crc, compression


def _check_chunk(view: memoryview, offset: int, body: int, length: int,
                 check: McapCheck) -> None:
    check.chunks += 1
    try:
        records, uncompressed_size, crc, _ = decompress_chunk(view, body, length)
    except Exception as exc:  # any decoder error means the chunk is damaged
        check.problems.append(f"chunk at byte {offset} cannot be read: {exc}")
        return
    if not crc:
        return
    check.chunk_crcs += 1
    if len(records) != uncompressed_size or zlib.crc32(records) != crc:
        check.problems.append(f"chunk at byte {offset} ({uncompressed_size} bytes) fails its "
                              "CRC: messages in it are damaged")
