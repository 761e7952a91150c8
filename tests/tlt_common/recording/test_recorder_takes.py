"""The recorder node in this process: its subscriptions are taken from, not called back.

No executor spins anything here until the test says so, so what reaches the file is exactly what
``take_queued`` (and ``stop``) took from the subscriptions' queues.
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile
from std_msgs.msg import Int32

from tlt_common.recording.mcap_writer import McapRecordingWriter
from tlt_common.recording.reading import read_messages
from tlt_common.recording.recorder import RecorderTiming, TopicRecorder
from tlt_common.recording.topic_filter import TopicFilter

TOPICS = ["/takes_test/a", "/takes_test/b", "/takes_test/c"]
PER_TOPIC = 600  # more than the 20 ms take period ever holds on the twin, fewer than a queue's 1000


@pytest.fixture
def context() -> Iterator[rclpy.Context]:
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    context.try_shutdown()


def wait_until(condition, what: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def recorded(path: Path) -> dict[str, list[int]]:
    by_topic: dict[str, list[int]] = defaultdict(list)
    for _, channel, _, msg in read_messages(path):
        by_topic[channel.topic].append(msg.data)
    return by_topic


def test_messages_queued_between_takes_are_all_written_in_order(context, tmp_path: Path):
    publisher_node = rclpy.create_node("takes_test_publisher", context=context)
    pubs = [publisher_node.create_publisher(Int32, t, QoSProfile(depth=PER_TOPIC)) for t in TOPICS]
    writer = McapRecordingWriter(tmp_path / "r.mcap")
    recorder = TopicRecorder(
        writer, TopicFilter(topics=TOPICS), node_name="takes_test_record", context=context
    )
    try:

        def subscribed() -> bool:
            recorder.discover()
            return all(p.get_subscription_count() for p in pubs)

        wait_until(subscribed, "the recorder to subscribe to every topic")
        assert "takes_test_record_topics" in publisher_node.get_node_names()
        for i in range(PER_TOPIC):
            for pub in pubs:
                pub.publish(Int32(data=i))
        taken = 0
        deadline = time.monotonic() + 30
        while taken < len(TOPICS) * PER_TOPIC and time.monotonic() < deadline:
            taken += recorder.take_queued()
            time.sleep(0.05)  # DDS may still be delivering the last of them
        assert taken == len(TOPICS) * PER_TOPIC
        for pub in pubs:
            pub.publish(Int32(data=PER_TOPIC))  # queued at the stop: written by it
        time.sleep(0.5)
        recorder.stop()
    finally:
        recorder.destroy_node()
        publisher_node.destroy_node()
        writer.close()
    assert recorded(writer.path) == {t: list(range(PER_TOPIC + 1)) for t in TOPICS}


def test_a_spinning_recorder_takes_on_its_timer(context, tmp_path: Path):
    publisher_node = rclpy.create_node("takes_test_publisher", context=context)
    pub = publisher_node.create_publisher(Int32, TOPICS[0], 10)
    writer = McapRecordingWriter(tmp_path / "r.mcap")
    recorder = TopicRecorder(
        writer,
        TopicFilter(topics=TOPICS[:1]),
        RecorderTiming(discovery_period_s=0.1, take_period_s=0.02),
        node_name="takes_test_record",
        context=context,
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    try:

        def spun_until(condition) -> bool:
            executor.spin_once(timeout_sec=0.02)
            return condition()

        wait_until(lambda: spun_until(pub.get_subscription_count), "the recorder to subscribe")
        for i in range(5):
            pub.publish(Int32(data=i))
        wait_until(
            lambda: spun_until(lambda: writer.message_count == 5), "the timer to take the five messages"
        )
        recorder.stop()
    finally:
        executor.shutdown()
        recorder.destroy_node()
        publisher_node.destroy_node()
        writer.close()
    assert recorded(writer.path) == {TOPICS[0]: [0, 1, 2, 3, 4]}
