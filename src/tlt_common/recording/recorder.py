"""The recorder node: finds every topic as it appears and writes each message it hears to MCAP.

Every ``discovery_period_s`` (wall time, so discovery goes on while a simulation is paused) it
lists the graph's topics. Each new topic that the :class:`TopicFilter` accepts and that has at
least one publisher gets a channel in the file and a ``raw`` subscription (the serialized CDR
bytes, never deserialized) whose QoS matches the publishers'
(:func:`tlt_common.recording.qos_profiles.subscription_qos`). A topic whose type has no importable
class or no installed definition is logged once and left out; a topic published with more than
one type records the first.

The recorded subscriptions live on a second node, ``<name>_topics``, that no executor spins: every
``take_period_s`` (wall time) the recorder takes whatever each of them has queued. An executor
rebuilds its wait set over every entity of its nodes each time it wakes, and with one wake per
message (some 70 topics, a few hundred messages a second on the twin) that bookkeeping would be
most of the recorder's CPU. The queues are deep (``SUBSCRIPTION_DEPTH``), so nothing is lost between
takes.

Each message is written with log time = the node clock when it was taken, at most one take period
after it arrived (ROS time: sim time when the node runs with ``use_sim_time``, 0 until the first
``/clock``), and publish time = its ``header.stamp`` when the type starts with a Header and the
stamp is set, else the log time.

Every ``flush_period_s`` the chunk in progress is closed and handed to the OS (what a killed
recorder keeps); every ``progress_period_s`` it logs topics and messages written. The node never
closes the file: its owner calls :meth:`McapRecordingWriter.close` after spinning ends.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rclpy.clock import Clock, ClockType
from rclpy.context import Context
from rclpy.exceptions import InvalidHandle
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

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
from tlt_common.ros.lean_node import LeanNode


@dataclass
class RecorderTiming:
    """Periods of the recorder's wall-clock timers, in seconds."""

    discovery_period_s: float = 0.5
    flush_period_s: float = 1.0
    progress_period_s: float = 10.0
    take_period_s: float = 0.02


@dataclass
class _Recorded:
    type_name: str
    channel_id: int
    has_header: bool
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
        context: Context | None = None,
    ) -> None:
        super().__init__(node_name, context=context)
        self._writer = writer
        self._filter = topic_filter or TopicFilter()
        self._timing = timing or RecorderTiming()
        self._definitions = definitions or MessageDefinitionSource()
        self._recorded: dict[str, _Recorded] = {}
        self._skipped: dict[str, str] = {}
        self._flushed_count = 0
        self._last_progress_count = 0
        # Its own arguments only: a remapped node name (``-r __node:=...``) would otherwise name
        # both nodes alike, and a sim-time parameter give it a /clock reader nobody reads.
        self._topics_node = LeanNode(
            f"{self.get_name()}_topics",
            context=self.context,
            use_global_arguments=False,
            enable_rosout=False,
            start_parameter_services=False,
        )
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(self._timing.take_period_s, self.take_queued, clock=wall)
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

    def take_queued(self) -> int:
        """Write every message the recorded subscriptions hold now; return how many."""
        log_time = self.get_clock().now().nanoseconds
        taken = 0
        for recorded in self._recorded.values():
            taken += self._take(recorded, log_time)
        return taken

    def flush(self) -> None:
        """Close the chunk in progress if anything arrived since the last flush."""
        if self._writer.message_count != self._flushed_count:
            self._writer.flush()
            self._flushed_count = self._writer.message_count

    def stop(self) -> None:
        """Write what is still queued, drop every subscription and flush."""
        self.take_queued()
        for recorded in self._recorded.values():
            self._topics_node.destroy_subscription(recorded.subscription)
        self.flush()

    def destroy_node(self) -> None:
        self._topics_node.destroy_node()
        super().destroy_node()

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
        subscription = self._subscribe(msg_class, topic, qos)
        self._recorded[topic] = _Recorded(type_name, channel_id, has_header, qos, subscription)
        self.get_logger().info(
            f"recording {topic} ({type_name}, {qos.reliability.short_key}, {qos.durability.short_key})"
        )

    def _resubscribe(self, topic: str, recorded: _Recorded, offered: list[QoSProfile]) -> None:
        # A publisher that arrived later offers less than the subscription requests, so it would
        # never be matched. Subscribing again with the weaker QoS keeps the same channel. (If the
        # new QoS is still transient local, the publishers' stored samples arrive a second time.)
        qos = subscription_qos(offered)
        self._take(recorded, self.get_clock().now().nanoseconds)
        self._topics_node.destroy_subscription(recorded.subscription)
        recorded.subscription = self._subscribe(import_message_type(recorded.type_name), topic, qos)
        recorded.qos = qos
        self.get_logger().info(
            f"re-subscribed {topic} ({qos.reliability.short_key}, {qos.durability.short_key}) "
            "to match a new publisher"
        )

    def _subscribe(self, msg_class: type, topic: str, qos: QoSProfile) -> Subscription:
        # Never called back: no executor spins the topics node; take_queued takes the messages.
        return self._topics_node.create_subscription(msg_class, topic, _never_called, qos, raw=True)

    def _take(self, recorded: _Recorded, log_time: int) -> int:
        """Write what ``recorded``'s subscription holds now, logged at ``log_time``."""
        writer, channel_id = self._writer, recorded.channel_id
        subscription = recorded.subscription
        taken = 0
        try:
            while True:
                with subscription.handle:
                    info = subscription.handle.take_message(subscription.msg_type, True)
                if info is None:
                    return taken
                data = info[0]
                stamp = header_stamp_ns(data) if recorded.has_header else None
                writer.write(channel_id, data, log_time, log_time if stamp is None else stamp)
                taken += 1
        except InvalidHandle:  # destroyed meanwhile
            return taken

    def _log_progress(self) -> None:
        total = self._writer.message_count
        self.get_logger().info(
            f"{len(self._recorded)} topics, {total} messages written "
            f"(+{total - self._last_progress_count} in the last "
            f"{self._timing.progress_period_s:g} s)"
        )
        self._last_progress_count = total


def _never_called(_data: bytes) -> None:
    raise AssertionError("the recorder's subscriptions are taken from, never called back")


def _compatible(requested: QoSProfile, offered: list[QoSProfile]) -> bool:
    """Whether a subscription with ``requested`` matches every publisher offering ``offered``."""
    for profile in offered:
        if (
            requested.reliability == ReliabilityPolicy.RELIABLE
            and profile.reliability != ReliabilityPolicy.RELIABLE
        ):
            return False
        if (
            requested.durability == DurabilityPolicy.TRANSIENT_LOCAL
            and profile.durability != DurabilityPolicy.TRANSIENT_LOCAL
        ):
            return False
    return True
