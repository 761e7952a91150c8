"""A node says so when a topic it lives on goes silent, whether DDS still matches the topic's
publisher to its subscription, and when the topic is heard again."""

from __future__ import annotations

import logging
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from tlt_common.bt.ros import TopicCache
from tlt_common.ros.topic_silence_watch import TopicSilenceWatch

SILENT = "nothing on"
AGAIN = "heard again"


def _said(caplog, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


@pytest.fixture
def nodes():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("listener", context=context)
    talker = Node("talker", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(talker)
    yield node, talker, executor
    executor.shutdown()
    node.destroy_node()
    talker.destroy_node()
    rclpy.shutdown(context=context)


def _run(executor, seconds: float, publish=None) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if publish is not None:
            publish()
        executor.spin_once(timeout_sec=0.02)


def test_a_silent_topic_is_reported_once_with_its_matched_publisher_then_its_return(nodes, caplog):
    node, talker, executor = nodes
    cache = TopicCache(node)
    cache.watch("/joints", String)
    publisher = talker.create_publisher(String, "/joints", 10)
    watch = TopicSilenceWatch(cache, ["/joints"], "ars_y", stall_s=1.0, period_s=0.1).start()
    try:
        with caplog.at_level(logging.WARNING, logger="tlt.topic_silence"):
            _run(executor, 1.5, lambda: publisher.publish(String(data="q")))
            assert cache.heard("/joints") is not None
            assert _said(caplog, SILENT) == []
            _run(executor, 2.5)
            silent = _said(caplog, SILENT)
            assert len(silent) == 1, silent  # once per silence, not once a period
            assert silent[0].startswith("ars_y: nothing on '/joints'"), silent
            assert "1 in this process's graph, 1 matched" in silent[0], silent
            assert "rediscovery" not in silent[0], "the publisher is matched: it just stopped"
            _run(executor, 0.5, lambda: publisher.publish(String(data="q")))
            assert len(_said(caplog, AGAIN)) == 1
        assert watch.silences == [("/joints", 1, 1)]
    finally:
        watch.stop()


def test_a_publisher_the_graph_knows_but_not_matched_is_named_as_such(nodes, caplog):
    # A best-effort publisher cannot feed a reliable subscription: DDS discovers it and never
    # matches it, which is how a participant rediscovered without its endpoints rematched looks.
    node, talker, executor = nodes
    cache = TopicCache(node)
    cache.watch("/ee", String)
    talker.create_publisher(String, "/ee", QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    watch = TopicSilenceWatch(cache, ["/ee"], "ars_y", stall_s=1.0, repeat_s=1.0, period_s=0.1).start()
    try:
        with caplog.at_level(logging.WARNING, logger="tlt.topic_silence"):
            _run(executor, 1.6)  # never heard since the watch started
            silent = _said(caplog, SILENT)
            assert len(silent) == 1, silent
            assert "1 in this process's graph, 0 matched" in silent[0], silent
            assert "did not rematch the endpoints" in silent[0], silent
            _run(executor, 1.0)  # still silent: said again, with what DDS sees now
            assert len(_said(caplog, SILENT)) == 2
        assert watch.silences == [("/ee", 1, 0), ("/ee", 1, 0)]
    finally:
        watch.stop()


def test_only_topics_the_cache_watches_can_be_watched(nodes):
    node, _, _ = nodes
    cache = TopicCache(node)
    cache.watch("/joints", String)
    with pytest.raises(ValueError, match="ars_y: not watched by the topic cache: /ee"):
        TopicSilenceWatch(cache, ["/joints", "/ee"], "ars_y")
