"""The file side of a recording: ROS 2 CDR messages into an MCAP file of the ``ros2`` profile.

Writes, through the ``mcap`` library's writer:
- one Schema per message type: name ``pkg/msg/Type``, encoding ``ros2msg``, the full definition
  text (see :mod:`tlt_common.recording.message_definitions`);
- one Channel per topic: message encoding ``cdr``, metadata ``offered_qos_profiles`` (the
  publishers' QoS, rosbag2 format) and ``topic_type_hash`` when the publisher told it;
- Messages: the serialized bytes as received (CDR with its 4-byte encapsulation header), the
  recorder's log time and publish time in nanoseconds, and a per-channel sequence number
  counting from 1 (gaps never occur: it counts what the recorder got);
- at :meth:`McapRecordingWriter.close`: the summary (schemas, channels, statistics, chunk
  indexes) and the footer, after which every MCAP tool opens the file.

Messages go into chunks (compressed with zstd or lz4 when the library can, else stored plain).
:meth:`flush` closes the chunk in progress and hands it to the OS, so a process killed later
loses nothing before that point (the file then lacks its summary and footer; see
:mod:`tlt_common.recording.recovery`).
"""

from __future__ import annotations

import os
import socket
import time
from collections import Counter
from pathlib import Path

import mcap.writer
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

LIBRARY = f"tlt-record ({LIBRARY_IDENTIFIER})"
PROFILE = "ros2"
_COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


def available_compressions() -> list[str]:
    """Compression names this installation can write, best first; always ends with ``none``."""
    # The mcap writer imports zstandard and lz4 optionally and leaves None where one is missing.
    names = []
    if getattr(mcap.writer, "zstandard", None) is not None:
        names.append("zstd")
    if getattr(mcap.writer, "lz4", None) is not None:
        names.append("lz4")
    names.append("none")
    return names


class McapRecordingWriter:
    """Writes one MCAP file. Not thread-safe: one thread (the recorder's executor) calls it.

    Opening fails with ``OSError`` when the file cannot be created, and with ``ValueError`` for a
    compression this installation cannot write; nothing is written then.
    """

    def __init__(
        self,
        path: str | Path,
        compression: str = "zstd",
        chunk_size: int = 1024 * 1024,
        metadata: dict[str, str] | None = None,
    ) -> None:
        if compression not in _COMPRESSIONS or compression not in available_compressions():
            raise ValueError(
                f"compression {compression!r} not available here; choose from "
                f"{', '.join(available_compressions())}"
            )
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=_COMPRESSIONS[compression])
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._sequence: Counter[int] = Counter()
        self.message_count = 0
        self.closed = False
        info = {
            "started_unix_ns": str(time.time_ns()),
            "hostname": socket.gethostname(),
            "ros_domain_id": os.environ.get("ROS_DOMAIN_ID", "0"),
            "compression": compression,
        }
        info.update(metadata or {})
        self._writer.add_metadata("tlt_recording", info)
        self._stream.flush()

    def add_channel(
        self,
        topic: str,
        type_name: str,
        definition: str,
        offered_qos_profiles: str,
        type_hash: str = "",
    ) -> int:
        """Register a topic (and its type's schema, once per type); return the channel id."""
        schema_id = self._schemas.get(type_name)
        if schema_id is None:
            schema_id = self._writer.register_schema(
                name=type_name, encoding=SchemaEncoding.ROS2, data=definition.encode("utf-8")
            )
            self._schemas[type_name] = schema_id
        metadata = {"offered_qos_profiles": offered_qos_profiles}
        if type_hash:
            metadata["topic_type_hash"] = type_hash
        return self._writer.register_channel(
            topic=topic, message_encoding=MessageEncoding.CDR, schema_id=schema_id, metadata=metadata
        )

    def write(self, channel_id: int, data: bytes, log_time_ns: int, publish_time_ns: int) -> None:
        """Add one serialized message to the current chunk."""
        self._sequence[channel_id] += 1
        self._writer.add_message(
            channel_id=channel_id,
            log_time=log_time_ns,
            data=data,
            publish_time=publish_time_ns,
            sequence=self._sequence[channel_id],
        )
        self.message_count += 1

    def flush(self) -> None:
        """Close the chunk in progress (if it has messages) and push the bytes to the OS."""
        if not self.closed:
            self._writer.flush()

    def close(self) -> None:
        """Write the summary and footer and close the file. Safe to call more than once."""
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.finish()
        finally:
            self._stream.close()
