"""The storage files of a bag, behind one Protocol (:class:`StorageFile`): MCAP with ``mcap``'s
writer (:class:`McapFile`: chunk, data-section and summary CRCs, rosbag2's ``ros2`` profile) and
sqlite3 with rosbags' ``Writer`` (:class:`Sqlite3File`); and a topic as both record it
(:class:`Topic`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import yaml

from .. import __version__
from .messages import typestore
from .metadata_yaml import DUMPER


class StorageFile(Protocol):
    """One storage file being written: topics connected to channels, messages written, then
    finished with the file's metadata (the text of its ``metadata.yaml`` share)."""

    channels: dict[str, int]
    """Topic name -> its channel in this file."""

    def connect(self, topic: Topic) -> int: ...

    def write(self, channel: int, timestamp: int, data: bytes | memoryview,
              publish_time: int | None = None) -> None: ...

    def write_batch(self, channels: Mapping[str, int],
                    batch: Sequence[tuple[int, str, bytes] | tuple[int, str, bytes, int]]
                    ) -> None: ...

    def finish(self, metadata: str) -> None: ...

    @property
    def path(self) -> Path: ...


CHUNK_SIZE = 2**20
"""An MCAP chunk is closed once it holds more than this many bytes (1 MiB, as before)."""


CHUNK_COMPRESSION = "ZSTD"
"""How an MCAP chunk's records are compressed (``mcap``'s ``CompressionType``; rosbag2's MCAP
storage, rosbags and ``mcap`` read zstd chunks, and the chunk CRC is over the records
uncompressed): a 501-sample trial's file takes 0.2 MiB, 0.7 MiB uncompressed (the ``/tf`` and
joint states repeat their names and frames every sample). Every message is kept."""


def qos_yaml(profiles: Sequence[dict[str, Any]]) -> str:
    """The ``offered_qos_profiles`` text of an MCAP channel, as rosbag2 Jazzy writes it
    (``serialize_rclcpp_qos_vector``: the version-9 profiles as a YAML block sequence, keys in
    ``rmw_qos_profile_t``'s order)."""
    if not profiles:
        return ""
    return str(yaml.dump(list(profiles), Dumper=DUMPER, sort_keys=False,
                         default_flow_style=False, width=10**9)).strip()


class McapFile:
    """One storage file written with ``mcap``'s :class:`~mcap.writer.Writer` (the format's
    reference implementation): chunked, each chunk zstd-compressed (:data:`CHUNK_COMPRESSION`),
    with chunk, data-section and summary CRCs, message and chunk indexes, statistics, and
    rosbag2's ``ros2`` profile (one ``ros2msg`` schema per type; channels carry
    ``offered_qos_profiles`` and ``topic_type_hash``; a ``rosbag2`` metadata record holds the
    file's metadata)."""

    def __init__(self, path: Path) -> None:
        from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, IndexType, Writer


        self.path = path
        self._handle = open(path, "wb")  # noqa: SIM115  (closed by finish)
        self._writer = Writer(self._handle, chunk_size=CHUNK_SIZE,
                              compression=CompressionType[CHUNK_COMPRESSION],
                              index_types=IndexType.ALL,
                              enable_crcs=True, enable_data_crcs=True)
        self._writer.start(profile="ros2",
                           library=f"exo_ilc_ros-{__version__}; {LIBRARY_IDENTIFIER}")
        self._schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        """Topic -> channel id, for the topics that have a message in this file."""

    def connect(self, topic: Topic) -> int:
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


class Sqlite3File:
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

    def connect(self, topic: Topic) -> int:
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
class Topic:
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
