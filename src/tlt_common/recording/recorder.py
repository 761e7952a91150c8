"""The recorder node: finds every topic as it appears and writes each message it hears to MCAP.

Every ``discovery_period_s`` (wall time, so discovery goes on while a simulation is paused) it
lists the graph's topics. Each new topic that the :class:`TopicFilter` accepts and that has at
least one publisher gets a channel in the file and a ``raw`` subscription (the serialized CDR
bytes, never deserialized) whose QoS matches the publishers'
(:func:`tlt_common.recording.qos_profiles.subscription_qos`). A topic whose type has no importable
class or no installed definition is logged once and left out; a topic published with more than
one type records the first.

Each message is written with log time = the node clock at receipt (ROS time: sim time when the
node runs with ``use_sim_time``, 0 until the first ``/clock``), and publish time = its
``header.stamp`` when the type starts with a Header and the stamp is set, else the log time.

Every ``flush_period_s`` the chunk in progress is closed and handed to the OS (what a killed
recorder keeps); every ``progress_period_s`` it logs topics and messages written. The node never
closes the file: its owner calls :meth:`McapRecordingWriter.close` after spinning ends.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidHandle
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from tlt_common.lean_node import LeanNode
from tlt_common.recording.header_stamp import header_stamp_ns
from tlt_common.recording.mcap_writer import McapRecordingWriter
from tlt_common.recording.message_definitions import (
    DefinitionNotFound,
    MessageDefinitionSource,
    first_field_is_header,
)
from tlt_common.recording.message_types import UnknownMessageType, import_message_type
from tlt_common.recording.qos_profiles import offered_qos_yaml, subscription_qos
from tlt_common.recording.topic_filter import TopicFilter

# Messages one callback takes from its subscription's queue beyond the one it was called with.
DRAIN_LIMIT = 500


@dataclass
class RecorderTiming:
    """Periods of the recorder's wall-clock timers, in seconds."""

    discovery_period_s: float = 0.5
    flush_period_s: float = 1.0
    progress_period_s: float = 10.0


@dataclass
class _Recorded:
    type_name: str
    channel_id: int
    qos: QoSProfile
    subscription: Subscription


@dataclass
class RecorderStats:
    """What has been recorded so far (read by the progress log and the final report)."""

    topics: int = 0
    messages: int = 0
    skipped: dict[str, str] = field(default_factory=dict)


class TopicRecorder(LeanNode):
    """Subscribes to every accepted topic and writes its messages through ``writer``."""

    def __init__(
        self,
        writer: McapRecordingWriter,
        topic_filter: TopicFilter | None = None,
        timing: RecorderTiming | None = None,
        definitions: MessageDefinitionSource | None = None,
        node_name: str = "tlt_record",
    ) -> None:
        super().__init__(node_name)
        self._writer = writer
        self._filter = topic_filter or TopicFilter()
        self._timing = timing or RecorderTiming()
        self._definitions = definitions or MessageDefinitionSource()
        self._recorded: dict[str, _Recorded] = {}
        self._skipped: dict[str, str] = {}
        self._flushed_count = 0
        self._last_progress_count = 0
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(self._timing.discovery_period_s, self.discover, clock=wall)
        self.create_timer(self._timing.flush_period_s, self.flush, clock=wall)
        self.create_timer(self._timing.progress_period_s, self._log_progress, clock=wall)
        self.get_logger().info(f"recording to {writer.path}")
        self.discover()

    @property
    def stats(self) -> RecorderStats:
        return RecorderStats(
            topics=len(self._recorded),
            messages=self._writer.message_count,
            skipped=dict(self._skipped),
        )

    def discover(self) -> None:
        """Subscribe to topics that appeared since the last call; re-match changed QoS offers."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._skipped or not self._filter.accepts(topic, types[0] if types else None):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # its QoS is unknown until someone publishes
            offered = [p.qos_profile for p in publishers]
            recorded = self._recorded.get(topic)
            if recorded is None:
                self._start(topic, types, publishers)
            elif not _compatible(recorded.qos, offered):
                self._resubscribe(topic, recorded, offered)

    def flush(self) -> None:
        """Close the chunk in progress if anything arrived since the last flush."""
        if self._writer.message_count != self._flushed_count:
            self._writer.flush()
            self._flushed_count = self._writer.message_count

    def stop(self) -> None:
        """Drop every subscription (no callback writes after this) and flush."""
        for recorded in self._recorded.values():
            self.destroy_subscription(recorded.subscription)
        self.flush()

    def _skip(self, topic: str, reason: str) -> None:
        self._skipped[topic] = reason
        self.get_logger().warning(f"not recording {topic}: {reason}")

    def _start(self, topic: str, types: list[str], publishers: list) -> None:
        type_name = types[0]
        if len(types) > 1:
            self.get_logger().warning(
                f"{topic} is published with several types {types}; recording {type_name} only"
            )
        try:
            msg_class = import_message_type(type_name)
            definition = self._definitions.full_text(type_name)
        except (UnknownMessageType, DefinitionNotFound) as exc:
            self._skip(topic, str(exc))
            return
        offered = [p.qos_profile for p in publishers if p.topic_type == type_name] or [
            p.qos_profile for p in publishers
        ]
        type_hash = str(getattr(publishers[0], "topic_type_hash", "") or "")
        channel_id = self._writer.add_channel(
            topic, type_name, definition, offered_qos_yaml(offered), type_hash
        )
        has_header = first_field_is_header(self._definitions.own_text(type_name))
        qos = subscription_qos(offered)
        subscription = self.create_subscription(
            msg_class, topic, self._callback(topic, channel_id, has_header), qos, raw=True
        )
        self._recorded[topic] = _Recorded(type_name, channel_id, qos, subscription)
        self.get_logger().info(
            f"recording {topic} ({type_name}, {qos.reliability.short_key}, "
            f"{qos.durability.short_key})"
        )

    def _resubscribe(self, topic: str, recorded: _Recorded, offered: list[QoSProfile]) -> None:
        # A publisher that arrived later offers less than the subscription requests, so it would
        # never be matched. Subscribing again with the weaker QoS keeps the same channel. (If the
        # new QoS is still transient local, the publishers' stored samples arrive a second time.)
        qos = subscription_qos(offered)
        self.destroy_subscription(recorded.subscription)
        msg_class = import_message_type(recorded.type_name)
        has_header = first_field_is_header(self._definitions.own_text(recorded.type_name))
        recorded.subscription = self.create_subscription(
            msg_class, topic, self._callback(topic, recorded.channel_id, has_header), qos, raw=True
        )
        recorded.qos = qos
        self.get_logger().info(
            f"re-subscribed {topic} ({qos.reliability.short_key}, {qos.durability.short_key}) "
            "to match a new publisher"
        )

    def _callback(self, topic: str, channel_id: int, has_header: bool) -> Callable[[bytes], None]:
        writer = self._writer
        clock = self.get_clock()

        def write(data: bytes) -> None:
            log_time = clock.now().nanoseconds
            stamp = header_stamp_ns(data) if has_header else None
            writer.write(channel_id, data, log_time, log_time if stamp is None else stamp)

        def on_message(data: bytes) -> None:
            write(data)
            # The executor hands over one message per pass over every entity, which is far
            # slower than DDS can deliver; take what else is queued now (bounded, so timers and
            # other topics still get their turn) before the reader's history overflows. The
            # subscription is looked up each time: a re-subscription replaces it.
            _drain(self._recorded[topic].subscription, write, DRAIN_LIMIT)

        return on_message

    def _log_progress(self) -> None:
        total = self._writer.message_count
        self.get_logger().info(
            f"{len(self._recorded)} topics, {total} messages written "
            f"(+{total - self._last_progress_count} in the last "
            f"{self._timing.progress_period_s:g} s)"
        )
        self._last_progress_count = total


def _drain(subscription: Subscription, write: Callable[[bytes], None], limit: int) -> int:
    """Take up to ``limit`` more queued raw messages from ``subscription``; return how many.

    Uses the subscription handle's ``take_message``, as rclpy's executor does; an rclpy without
    it, or a subscription destroyed meanwhile, just takes nothing more.
    """
    taken = 0
    try:
        while taken < limit:
            with subscription.handle:
                info = subscription.handle.take_message(subscription.msg_type, True)
            if info is None:
                break
            write(info[0])
            taken += 1
    except (AttributeError, InvalidHandle):
        pass
    return taken


def _compatible(requested: QoSProfile, offered: list[QoSProfile]) -> bool:
    """Whether a subscription with ``requested`` matches every publisher offering ``offered``."""
    for profile in offered:
        if (requested.reliability == ReliabilityPolicy.RELIABLE
                and profile.reliability != ReliabilityPolicy.RELIABLE):
            return False
        if (requested.durability == DurabilityPolicy.TRANSIENT_LOCAL
                and profile.durability != DurabilityPolicy.TRANSIENT_LOCAL):
            return False
    return True
