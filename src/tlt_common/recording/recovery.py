"""Get the messages out of a recording whose recorder died before finishing the file.

A recorder killed with SIGKILL (or by a crash or power loss) leaves the header, the metadata and
every chunk it had flushed, but no summary and no footer. The standard seeking readers look for the
footer first and fail on such a file; reading it front to back with ``mcap``'s ``StreamReader``
yields every complete record until the cut. :func:`iter_flushed_messages` does that and stops
quietly at the first record it cannot read; :func:`recover` copies what it found into a new,
complete file that every MCAP tool opens (the same job as the ``mcap recover`` command of the
MCAP CLI).

``tlt-mcap-recover SRC DST`` (:func:`main`) runs :func:`recover`. Exit 0: DST written (it says
how many messages and whether SRC was complete); 2: SRC unreadable (not MCAP, no such file) or DST
cannot be written, and DST is then not created.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from tlt_common.recording.mcap_writer import LIBRARY, PROFILE, available_compressions


@dataclass
class ScanResult:
    """How a front-to-back read of a file ended."""

    complete: bool = False  # the footer was reached
    stopped_at: str = ""  # why reading stopped early, when it did


@dataclass
class RecoveryReport:
    messages: int
    channels: int
    complete: bool
    stopped_at: str


def iter_flushed_records(
    path: str | Path, result: ScanResult | None = None
) -> Iterator[Schema | Channel | Message | Metadata]:
    """Schemas, channels, metadata and messages of a possibly cut file, in file order.

    Raises ``McapError`` when the file does not start as an MCAP file; otherwise stops at the
    first unreadable record and notes why in ``result``.
    """
    result = result if result is not None else ScanResult()
    with open(path, "rb") as stream:
        records = StreamReader(stream).records
        first = True
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception as exc:  # any cut-off record: short read, bad length, bad compression
                if first:
                    raise McapError(f"{path}: not an MCAP file: {exc!r}") from None
                result.stopped_at = f"{type(exc).__name__}: {exc}".rstrip(": ")
                return
            first = False
            if isinstance(record, Footer):
                result.complete = True
            elif isinstance(record, (Schema, Channel, Message, Metadata)):
                yield record


def iter_flushed_messages(
    path: str | Path, result: ScanResult | None = None
) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """``(schema, channel, message)`` for every message that reached the file, in file order."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    for record in iter_flushed_records(path, result):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message):
            channel = channels.get(record.channel_id)
            if channel is not None:
                yield schemas.get(channel.schema_id), channel, record


def recover(src: str | Path, dst: str | Path) -> RecoveryReport:
    """Write every message that reached ``src`` into a complete MCAP file ``dst``.

    Raises ``McapError`` (nothing written) when ``src`` is not an MCAP file.
    """
    dst = Path(dst)
    result = ScanResult()
    records = iter_flushed_records(src, result)
    first = next(records, None)  # raises before dst is created if src is not MCAP
    tmp = dst.with_name(dst.name + ".partial")
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    messages = 0
    compression = CompressionType.ZSTD if "zstd" in available_compressions() else CompressionType.NONE
    try:
        with open(tmp, "wb") as stream:
            writer = Writer(stream, compression=compression)
            writer.start(profile=PROFILE, library=LIBRARY)
            for record in _chain(first, records):
                if isinstance(record, Schema):
                    schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                elif isinstance(record, Channel):
                    channel_ids[record.id] = writer.register_channel(
                        record.topic,
                        record.message_encoding,
                        schema_ids.get(record.schema_id, 0),
                        dict(record.metadata),
                    )
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, dict(record.metadata))
                elif isinstance(record, Message) and record.channel_id in channel_ids:
                    writer.add_message(
                        channel_ids[record.channel_id],
                        record.log_time,
                        record.data,
                        record.publish_time,
                        record.sequence,
                    )
                    messages += 1
            writer.finish()
        tmp.replace(dst)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return RecoveryReport(messages, len(channel_ids), result.complete, result.stopped_at)


def _chain(first, rest):
    if first is not None:
        yield first
    yield from rest


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="tlt-mcap-recover",
        description="Copy every message a cut MCAP recording holds into a complete file.",
    )
    parser.add_argument("src", type=Path, help="the cut recording")
    parser.add_argument("dst", type=Path, help="the complete file to write")
    args = parser.parse_args(argv)
    if args.src.resolve() == args.dst.resolve():
        print("tlt-mcap-recover: SRC and DST must differ", file=sys.stderr)
        return 2
    try:
        report = recover(args.src, args.dst)
    except (OSError, McapError) as exc:
        print(f"tlt-mcap-recover: {exc}", file=sys.stderr)
        return 2
    state = "complete" if report.complete else f"cut ({report.stopped_at or 'no footer'})"
    print(
        f"tlt-mcap-recover: {report.messages} messages on {report.channels} channels "
        f"from {args.src} ({state}) -> {args.dst}"
    )
    return 0
