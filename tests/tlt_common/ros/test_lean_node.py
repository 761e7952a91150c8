"""LeanNode: publishers and subscriptions without rclpy's default QoS-event handlers (each one a
waitable in every wait set the executor builds), unless a caller or TLT_QOS_EVENTS asks for them."""

from __future__ import annotations

import rclpy
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

from tlt_common.ros.lean_node import QOS_EVENTS_ENV, LeanNode


def _node(name: str):
    context = rclpy.Context()
    rclpy.init(context=context)
    return context, LeanNode(name, context=context)


def test_no_default_event_handlers_but_asked_ones_kept_and_messages_flow(monkeypatch):
    monkeypatch.delenv(QOS_EVENTS_ENV, raising=False)
    context, node = _node("lean_test")
    try:
        pub = node.create_publisher(String, "lean_chatter", 10)
        got: list[str] = []
        sub = node.create_subscription(String, "lean_chatter", lambda m: got.append(m.data), 10)
        assert pub.event_handlers == [] and sub.event_handlers == []
        asked = node.create_subscription(
            String, "lean_chatter", lambda m: None, 10,
            event_callbacks=SubscriptionEventCallbacks(incompatible_qos=print, use_default_callbacks=False),
        )  # fmt: skip
        assert len(asked.event_handlers) == 1
        # The node's own /clock and /parameter_events entities go through the same methods.
        assert all(not p.event_handlers for p in node.publishers)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        for _ in range(50):
            pub.publish(String(data="hello"))
            executor.spin_once(timeout_sec=0.05)
            if got:
                break
        assert got and got[0] == "hello"
    finally:
        node.destroy_node()
        context.try_shutdown()


def test_the_environment_brings_rclpys_default_handlers_back(monkeypatch):
    monkeypatch.setenv(QOS_EVENTS_ENV, "1")
    context, node = _node("lean_test_defaults")
    try:
        sub = node.create_subscription(String, "lean_chatter", lambda m: None, 10)
        pub = node.create_publisher(String, "lean_chatter", 10)
        assert sub.event_handlers and pub.event_handlers
    finally:
        node.destroy_node()
        context.try_shutdown()
