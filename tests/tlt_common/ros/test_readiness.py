"""ReadinessWatch against real ReadinessPublishers: it counts every word, so a restarted process
(a new publisher saying what the old one said) is a new word."""

from __future__ import annotations

import time

import rclpy
from rclpy.executors import SingleThreadedExecutor

from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.readiness import ReadinessPublisher, ReadinessWatch

TOPIC = "/test_readiness/status"


def test_every_word_is_counted_and_a_restarted_process_is_a_new_word():
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    nodes = [rclpy.create_node(name, context=context) for name in ("watcher", "server", "server_again")]
    for node in nodes:
        executor.add_node(node)

    def spin_until(predicate, what: str) -> None:
        deadline = time.monotonic() + 10.0
        while not predicate():
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            executor.spin_once(timeout_sec=0.05)

    try:
        watch = ReadinessWatch(nodes[0], TOPIC)
        assert watch.heard() == 0 and watch.not_ready() == "has not said it is ready"
        first = ReadinessPublisher(nodes[1], TOPIC, "server")
        first.say("no joint state yet")
        spin_until(lambda: watch.heard() == 1, "the first word")
        assert watch.not_ready() == "no joint state yet"
        first.say("no joint state yet")  # the same reason is not said twice
        first.say("")
        spin_until(lambda: watch.heard() == 2, "ready")
        assert watch.not_ready() == ""
        gone = nodes.pop(1)  # the process dies; its successor says ready at once
        executor.remove_node(gone)
        destroy_node(gone)
        ReadinessPublisher(nodes[1], TOPIC, "server").say("")
        spin_until(lambda: watch.heard() == 3, "the restarted process's word")
        assert watch.not_ready() == ""
    finally:
        executor.shutdown(timeout_sec=2.0)
        for node in nodes:
            destroy_node(node)
        rclpy.shutdown(context=context)
