"""Chosen topics of a recording as CSV files: one per topic, one row per message.

The first column, ``log_time``, is the message's log time in seconds (exact: the nanoseconds
after the point). The other columns are the message's fields in definition order, nested
messages flattened with dotted names (``header.stamp.sec``) and arrays (variable or fixed size,
``uint8[]`` included) written as one JSON text each (``[1.0, 2.5]``, nested messages in an array
as JSON objects). Messages are decoded from the schemas stored in the recording, so the
interface packages need not be installed. A recording cut short (killed recorder) is exported up
to its last flushed chunk. The file of topic ``/crs/tree_status`` is ``crs.tree_status.csv``.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from mcap.records import Channel

from tlt_common.recording.reading import LenientRos2DecoderFactory
from tlt_common.recording.recovery import ScanResult, iter_flushed_messages, iter_flushed_records
from tlt_common.recording.summary import NS_PER_S


class UnknownTopics(LookupError):
    """Topics asked for that the recording does not have."""


def csv_name(topic: str) -> str:
    """``/crs/tree_status`` -> ``crs.tree_status.csv`` (ROS names have no dots, so it is unique)."""
    return topic.strip("/").replace("/", ".") + ".csv"


def flatten(message: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """``(dotted name, value)`` of every leaf field of a decoded message, in definition order."""
    for name in message.__slots__:
        value = getattr(message, name)
        key = f"{prefix}{name}"
        if hasattr(value, "__slots__"):
            yield from flatten(value, f"{key}.")
        elif isinstance(value, (list, tuple, bytes, bytearray)):
            yield key, json.dumps(_plain(value))
        else:
            yield key, value


def _plain(value: Any) -> Any:
    """A decoded value as JSON-ready data: messages as objects, byte arrays as integer lists."""
    if hasattr(value, "__slots__"):
        return {name: _plain(getattr(value, name)) for name in value.__slots__}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def log_time_text(ns: int) -> str:
    return f"{ns // NS_PER_S}.{ns % NS_PER_S:09d}"


@dataclass
class _TopicFile:
    path: Path
    stream: TextIO
    writer: Any = None  # csv writer, made with the columns of the first message
    columns: list[str] = field(default_factory=list)
    rows: int = 0


@dataclass
class ExportReport:
    rows: dict[str, int]  # topic -> rows written
    files: dict[str, Path]  # topic -> CSV file
    complete: bool  # False: the recording was cut short and only its flushed part exported
    stopped_at: str


def export_csv(path: str | Path, topics: Sequence[str], out_dir: str | Path) -> ExportReport:
    """Write one CSV per topic in ``topics`` (exact names) into ``out_dir`` (created).

    Raises ``OSError`` / ``McapError`` for a file that cannot be read or is not MCAP, and
    :class:`UnknownTopics` (nothing written) when a topic is not in the recording.
    """
    wanted = set(topics)
    result = ScanResult()
    channels: dict[int, Channel] = {}
    for record in iter_flushed_records(path, result):
        if isinstance(record, Channel):
            channels[record.id] = record
    missing = wanted - {c.topic for c in channels.values()}
    if missing:
        raise UnknownTopics(
            f"{path} has no topic {', '.join(sorted(missing))} "
            f"(it has: {', '.join(sorted({c.topic for c in channels.values()}))})"
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    factory = LenientRos2DecoderFactory()
    decoders: dict[int, Callable[[bytes], Any] | None] = {}
    files: dict[str, _TopicFile] = {}
    try:
        for topic in sorted(wanted):
            target = out / csv_name(topic)
            files[topic] = _TopicFile(target, open(target, "w", newline="", encoding="utf-8"))  # noqa: SIM115
        for schema, channel, record in iter_flushed_messages(path):
            if channel.topic not in wanted:
                continue
            if record.channel_id not in decoders:
                decoders[record.channel_id] = factory.decoder_for(channel.message_encoding, schema)
            decoder = decoders[record.channel_id]
            if decoder is None:
                raise ValueError(f"{channel.topic}: no decoder for encoding {channel.message_encoding!r}")
            _write_row(files[channel.topic], record.log_time, decoder(record.data))
    finally:
        for f in files.values():
            if f.writer is None:  # no message: the header of the log time alone
                csv.writer(f.stream).writerow(["log_time"])
            f.stream.close()
    return ExportReport(
        {t: f.rows for t, f in files.items()},
        {t: f.path for t, f in files.items()},
        result.complete,
        result.stopped_at,
    )


def _write_row(f: _TopicFile, log_time_ns: int, decoded: Any) -> None:
    fields = list(flatten(decoded))
    if f.writer is None:
        f.columns = ["log_time", *(name for name, _ in fields)]
        f.writer = csv.writer(f.stream)
        f.writer.writerow(f.columns)
    f.writer.writerow([log_time_text(log_time_ns), *(value for _, value in fields)])
    f.rows += 1


__all__ = ["ExportReport", "UnknownTopics", "csv_name", "export_csv", "flatten"]
