"""Replay a recording into the ROS graph: each message on its topic, at its recorded timing.

:func:`open_recording` reads what a replay needs before it starts: the channels (topic, type,
stored QoS) and the first and last log time. A complete file is read through its summary and its
messages come in log-time order; a file cut short (killed recorder) is scanned front to back once
and its flushed messages come in file order (the order the recorder wrote them).

:class:`RecordingPlayer` makes one publisher per played topic, of the recorded type and with the
QoS the recorded publishers offered (:func:`~tlt_common.recording.qos_profiles.playback_qos`),
and publishes the recorded CDR bytes as they are, never decoded. A message recorded ``t``
seconds after the recording's first message goes out ``t / rate`` seconds after the replay
starts, whichever topics are played, so a replay of some topics keeps their timing against the
whole run. With ``clock`` it publishes ``rosgraph_msgs/Clock`` on ``/clock`` at ``clock_hz``
(wall time), the recorded time the replay has reached, so nodes with ``use_sim_time`` run on the
recording's time; a recorded ``/clock`` is then not replayed. Stopping (the ``stop`` list
non-empty) ends it between messages.
"""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile

from tlt_common.recording.message_types import UnknownMessageType, import_message_type
from tlt_common.recording.qos_profiles import playback_qos
from tlt_common.recording.recovery import ScanResult, iter_flushed_messages, iter_flushed_records
from tlt_common.recording.summary import NS_PER_S

CLOCK_TOPIC = "/clock"
CHECK_PERIOD_S = 0.1  # longest sleep before the stop flag is looked at again


@dataclass
class RecordingContents:
    """What a replay of ``path`` needs to know before it starts."""

    path: Path
    complete: bool
    stopped_at: str
    channels: dict[int, Channel]
    type_names: dict[int, str]  # channel id -> ``pkg/msg/Type``
    start_ns: int  # log time of the first message (0 when there is none)
    end_ns: int

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS_PER_S

    def messages(self, channel_ids: Iterable[int]) -> Iterator[tuple[Channel, Message]]:
        """The messages of ``channel_ids``: in log-time order (complete file) or file order (cut)."""
        wanted = set(channel_ids)
        if not self.complete:
            for _, channel, message in iter_flushed_messages(self.path):
                if channel.id in wanted:
                    yield channel, message
            return
        topics = sorted({self.channels[i].topic for i in wanted})
        with open(self.path, "rb") as stream:
            for _, channel, message in make_reader(stream).iter_messages(topics=topics, log_time_order=True):
                if channel.id in wanted:
                    yield channel, message


def open_recording(path: str | Path) -> RecordingContents:
    """Read ``path``'s channels and time span. Raises ``OSError`` (cannot open) or ``McapError``
    (not an MCAP file)."""
    path = Path(path)
    with open(path, "rb") as stream:
        try:
            summary = make_reader(stream).get_summary()
        except Exception:  # a cut file fails in many ways; it is scanned below
            summary = None
    if summary is not None and summary.statistics is not None:
        stats = summary.statistics
        empty = stats.message_count == 0
        return RecordingContents(
            path,
            True,
            "",
            dict(summary.channels),
            {i: _type_name(summary.schemas.get(c.schema_id)) for i, c in summary.channels.items()},
            0 if empty else stats.message_start_time,
            0 if empty else stats.message_end_time,
        )
    result = ScanResult()
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    first = last = None
    for record in iter_flushed_records(path, result):
        if isinstance(record, Message):
            first = record.log_time if first is None else min(first, record.log_time)
            last = record.log_time if last is None else max(last, record.log_time)
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Schema):
            schemas[record.id] = record
    return RecordingContents(
        path,
        result.complete,
        result.stopped_at,
        channels,
        {i: _type_name(schemas.get(c.schema_id)) for i, c in channels.items()},
        first or 0,
        last or 0,
    )


def _type_name(schema: Schema | None) -> str:
    return schema.name if schema is not None else ""


@dataclass
class PlayOptions:
    rate: float = 1.0  # 2.0: twice as fast as recorded
    topics: Sequence[str] | None = None  # regular expressions matched against whole topic names
    clock: bool = False
    clock_hz: float = 100.0
    delay_s: float = 0.0  # wait after making the publishers, before the first message
    wait_for_subscribers: bool = False  # wait until every played topic has a subscriber
    progress_period_s: float = 1.0


@dataclass
class PlayReport:
    published: dict[str, int] = field(default_factory=dict)  # topic (as published) -> messages
    played_s: float = 0.0  # recorded seconds replayed
    stopped: bool = False  # stopped before the end


class RecordingPlayer:
    """Publishes a recording on ``node`` (see the module text). Raises ``ValueError`` for a
    topic pattern that is not a regular expression or a rate that is not positive."""

    def __init__(
        self, node: Node, recording: RecordingContents, options: PlayOptions, out: TextIO = sys.stdout
    ) -> None:
        if not options.rate > 0:
            raise ValueError(f"rate must be > 0, got {options.rate}")
        if options.clock and not options.clock_hz > 0:
            raise ValueError(f"clock rate must be > 0, got {options.clock_hz}")
        patterns = [_compile(p) for p in options.topics or ()]
        self.node = node
        self.recording = recording
        self.options = options
        self.out = out
        self.skipped: dict[str, str] = {}  # topic -> why it is not played
        self._publishers: dict[int, Publisher] = {}
        by_topic: dict[str, Publisher] = {}
        for channel_id, channel in sorted(recording.channels.items()):
            topic = channel.topic
            if patterns and not any(p.fullmatch(topic) for p in patterns):
                continue
            if options.clock and topic == CLOCK_TOPIC:
                self.skipped[topic] = "the replay publishes its own clock (--clock)"
                continue
            if topic not in by_topic:
                type_name = recording.type_names.get(channel_id, "")
                try:
                    msg_class = import_message_type(type_name)
                except UnknownMessageType as exc:
                    self.skipped[topic] = str(exc)
                    continue
                qos = playback_qos(channel.metadata.get("offered_qos_profiles", ""))
                by_topic[topic] = node.create_publisher(msg_class, topic, qos)
            self._publishers[channel_id] = by_topic[topic]
        self._clock = None
        if options.clock:
            from rosgraph_msgs.msg import Clock

            self._clock = node.create_publisher(Clock, CLOCK_TOPIC, QoSProfile(depth=10))

    @property
    def topics(self) -> list[str]:
        return sorted({p.topic_name for p in self._publishers.values()})

    def play(self, stop: Sequence[object] = ()) -> PlayReport:
        """Publish every played message at its time; return early once ``stop`` is non-empty."""
        report = PlayReport(published=dict.fromkeys(self.topics, 0))
        if not self._wait_before_start(stop):
            report.stopped = True
            return report
        rate = self.options.rate
        start_ns = self.recording.start_ns
        total_s = self.recording.duration_s
        clock_period = 1.0 / self.options.clock_hz if self._clock is not None else float("inf")
        wall0 = time.monotonic()
        next_clock = wall0
        next_progress = wall0 + self.options.progress_period_s

        def recorded_now(now: float) -> int:  # never past the end, so the clock ends on it
            return min(self.recording.end_ns, start_ns + int((now - wall0) * rate * NS_PER_S))

        for channel, message in self.recording.messages(self._publishers):
            target = wall0 + (message.log_time - start_ns) / NS_PER_S / rate
            while True:
                if stop:
                    report.stopped = True
                    break
                now = time.monotonic()
                if now >= next_clock:
                    self._publish_clock(recorded_now(now))
                    next_clock = _next_due(next_clock, clock_period, now)
                if now >= next_progress:
                    played = max(0, recorded_now(now) - start_ns) / NS_PER_S
                    self._print(
                        f"played {played:.1f} / {total_s:.1f} s, {sum(report.published.values())} messages"
                    )
                    next_progress = _next_due(next_progress, self.options.progress_period_s, now)
                if now >= target:
                    break
                time.sleep(min(target, next_clock, next_progress, now + CHECK_PERIOD_S) - now)
            if report.stopped:
                break
            publisher = self._publishers[channel.id]
            publisher.publish(message.data)
            report.published[publisher.topic_name] += 1
            report.played_s = max(report.played_s, (message.log_time - start_ns) / NS_PER_S)
        if not report.stopped:
            report.played_s = total_s
            self._publish_clock(self.recording.end_ns)
        return report

    def _wait_before_start(self, stop: Sequence[object]) -> bool:
        if self.options.wait_for_subscribers:
            publishers = {p.topic_name: p for p in self._publishers.values()}
            if self._clock is not None:
                publishers[CLOCK_TOPIC] = self._clock
            said = False
            while not stop:
                waiting = sorted(t for t, p in publishers.items() if p.get_subscription_count() == 0)
                if not waiting:
                    break
                if not said:
                    self._print(f"waiting for a subscriber on {', '.join(waiting)}")
                    said = True
                time.sleep(CHECK_PERIOD_S)
        deadline = time.monotonic() + self.options.delay_s
        while not stop and time.monotonic() < deadline:
            time.sleep(min(CHECK_PERIOD_S, max(0.0, deadline - time.monotonic())))
        if self._clock is not None and not stop:
            self._publish_clock(self.recording.start_ns)
        return not stop

    def _publish_clock(self, ns: int) -> None:
        if self._clock is None:
            return
        from rosgraph_msgs.msg import Clock

        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(ns, NS_PER_S)
        self._clock.publish(msg)

    def _print(self, text: str) -> None:
        print(f"tlt record play: {text}", file=self.out, flush=True)


def _next_due(due: float, period: float, now: float) -> float:
    """The next time a periodic action is due; one that fell behind restarts from now."""
    due += period
    return due if due > now else now + period


def _compile(pattern: str) -> re.Pattern[str]:
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise ValueError(f"topic pattern {pattern!r} is not a regular expression: {exc}") from None


__all__ = ["PlayOptions", "PlayReport", "RecordingContents", "RecordingPlayer", "open_recording"]
