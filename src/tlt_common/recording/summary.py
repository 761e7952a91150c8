"""What a recording holds, per topic: type, message count, first and last log time, mean rate.

:func:`summarise` reads the file front to back (:func:`~tlt_common.recording.recovery.iter_flushed_records`),
so a recording whose recorder was killed is summarised too, up to its last flushed chunk, and the
summary says it was cut and why reading stopped. Only the records' headers are looked at; no
message is decoded. A missing file raises ``OSError``, a file that is not MCAP ``McapError``.
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Channel, Message, Metadata, Schema

from tlt_common.recording.recovery import ScanResult, iter_flushed_records

NS_PER_S = 1_000_000_000
# Log times above this are wall time (since 1970), below it sim time (since the twin started).
_WALL_TIME_NS = 10**9 * NS_PER_S


@dataclass
class TopicSummary:
    topic: str
    type_name: str
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0

    @property
    def rate_hz(self) -> float | None:
        """Mean rate while the topic was published: intervals over their total span."""
        span = self.last_ns - self.first_ns
        if self.count < 2 or span <= 0:
            return None
        return (self.count - 1) * NS_PER_S / span


@dataclass
class RecordingSummary:
    path: Path
    complete: bool  # the file has its footer (the recorder finished it)
    stopped_at: str  # why reading stopped early, for a cut file
    topics: dict[str, TopicSummary] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def start_ns(self) -> int | None:
        firsts = [t.first_ns for t in self.topics.values() if t.count]
        return min(firsts) if firsts else None

    @property
    def end_ns(self) -> int | None:
        lasts = [t.last_ns for t in self.topics.values() if t.count]
        return max(lasts) if lasts else None

    @property
    def duration_s(self) -> float:
        if self.start_ns is None or self.end_ns is None:
            return 0.0
        return (self.end_ns - self.start_ns) / NS_PER_S


def summarise(path: str | Path) -> RecordingSummary:
    """Count every message that reached ``path``, per topic (see the module text)."""
    result = ScanResult()
    schemas: dict[int, str] = {}
    channels: dict[int, TopicSummary] = {}
    summary = RecordingSummary(Path(path), complete=False, stopped_at="")
    for record in iter_flushed_records(path, result):
        if isinstance(record, Message):
            topic = channels.get(record.channel_id)
            if topic is None:
                continue
            if topic.count == 0 or record.log_time < topic.first_ns:
                topic.first_ns = record.log_time
            if topic.count == 0 or record.log_time > topic.last_ns:
                topic.last_ns = record.log_time
            topic.count += 1
        elif isinstance(record, Schema):
            schemas[record.id] = record.name
        elif isinstance(record, Channel):
            if record.id not in channels:  # the summary section repeats every channel
                topic = summary.topics.get(record.topic)
                if topic is None:
                    topic = TopicSummary(record.topic, schemas.get(record.schema_id, ""))
                    summary.topics[record.topic] = topic
                channels[record.id] = topic
        elif isinstance(record, Metadata):
            summary.metadata[record.name] = dict(record.metadata)
    summary.complete = result.complete
    summary.stopped_at = result.stopped_at
    return summary


def _time_text(ns: int) -> str:
    seconds = f"{ns // NS_PER_S}.{ns % NS_PER_S:09d} s"
    if ns < _WALL_TIME_NS:
        return f"{seconds} (sim time)"
    utc = datetime.datetime.fromtimestamp(ns // NS_PER_S, tz=datetime.UTC)
    return f"{seconds} ({utc:%Y-%m-%d %H:%M:%S}.{ns % NS_PER_S // 1_000_000:03d} UTC)"


def format_summary(summary: RecordingSummary) -> str:
    """The text ``tlt record info`` prints."""
    if summary.complete:
        state = "complete"
    else:
        why = summary.stopped_at or "no footer"
        state = f"CUT SHORT ({why}): the messages before the cut; tlt-mcap-recover makes a complete copy"
    lines = [f"file:      {summary.path} ({state})"]
    start, end = summary.start_ns, summary.end_ns
    if start is not None and end is not None:
        lines += [f"start:     {_time_text(start)}", f"end:       {_time_text(end)}"]
    lines += [
        f"duration:  {summary.duration_s:.3f} s",
        f"messages:  {summary.message_count} on {len(summary.topics)} topics",
    ]
    info = summary.metadata.get("tlt_recording", {})
    if info.get("hostname"):
        lines.append(f"recorded:  on {info['hostname']}, ROS domain {info.get('ros_domain_id', '?')}")
    if not summary.topics:
        return "\n".join(lines)
    width = max(len("topic"), *(len(t) for t in summary.topics))
    type_width = max(len("type"), *(len(t.type_name) for t in summary.topics.values()))
    lines.append("")
    lines.append(
        f"{'topic':<{width}}  {'type':<{type_width}}  {'count':>8}  "
        f"{'first s':>10}  {'last s':>10}  {'rate Hz':>9}"
    )
    base = start or 0
    for name in sorted(summary.topics):
        t = summary.topics[name]
        if t.count:
            first = f"{(t.first_ns - base) / NS_PER_S:10.3f}"
            last = f"{(t.last_ns - base) / NS_PER_S:10.3f}"
        else:
            first = last = f"{'-':>10}"
        rate = f"{t.rate_hz:9.2f}" if t.rate_hz is not None else f"{'-':>9}"
        lines.append(f"{name:<{width}}  {t.type_name:<{type_width}}  {t.count:>8}  {first}  {last}  {rate}")
    lines.append("(first s, last s: from the start of the recording; rate: mean over the topic's own span)")
    return "\n".join(lines)


__all__ = ["RecordingSummary", "TopicSummary", "format_summary", "summarise"]
