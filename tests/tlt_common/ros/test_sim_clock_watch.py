"""A node on sim time says so when /clock stops reaching it, and when it comes back."""

from __future__ import annotations

import logging
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from tlt_common.ros.sim_clock_watch import watch_sim_clock

STALLED = "no /clock for"
AGAIN = "sim time moves again"


def _said(caplog, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


def test_a_stopped_clock_is_reported_once_with_the_threads_then_its_return(caplog, capfd):
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("watched", context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
    twin = Node("clock_source", context=context)
    clock = twin.create_publisher(Clock, "/clock", 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    sim_ns = [0]

    def run(seconds: float, publish: bool) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if publish:
                sim_ns[0] += 20_000_000
                clock.publish(Clock(clock=rclpy.time.Time(nanoseconds=sim_ns[0]).to_msg()))
            executor.spin_once(timeout_sec=0.02)

    watch = watch_sim_clock(node, stall_s=1.0, period_s=0.1)
    try:
        with caplog.at_level(logging.WARNING, logger="tlt.sim_clock"):
            run(1.5, publish=True)
            assert node.get_clock().now().nanoseconds > 0, "the node hears /clock"
            assert _said(caplog, STALLED) == []
            run(2.5, publish=False)
            stalled = _said(caplog, STALLED)
            assert len(stalled) == 1, stalled  # once per stall, not once a period
            assert stalled[0].startswith("watched:"), stalled
            stacks = capfd.readouterr().err
            assert "Current thread" in stacks and "\nThread 0x" in stacks, "every thread's stack follows"
            assert "test_sim_clock_watch.py" in stacks, "the main thread's, where it is now"
            run(0.5, publish=True)
            assert len(_said(caplog, AGAIN)) == 1
        assert watch.stalls == 1
    finally:
        watch.stop()
        executor.shutdown()
        node.destroy_node()
        twin.destroy_node()
        rclpy.try_shutdown(context=context)


def test_no_watch_on_the_wall_clock():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("on_wall_time", context=context)
    try:
        assert watch_sim_clock(node) is None
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
