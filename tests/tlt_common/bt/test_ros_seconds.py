"""node_clock: ROS time in seconds, read from the system clock while no simulated time is active
and from rclpy's clock once use_sim_time switches it on (and back off)."""

from __future__ import annotations

import time

import rclpy
from rclpy.parameter import Parameter
from rclpy.time import Time

from tlt_common.bt.ros import RosSeconds, node_clock


def test_node_clock_follows_ros_time_with_and_without_simulated_time():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("ros_seconds_test", context=context)
    try:
        seconds = node_clock(node)
        assert isinstance(seconds, RosSeconds) and not seconds.simulated
        before = node.get_clock().now().nanoseconds * 1e-9
        value = seconds()
        after = node.get_clock().now().nanoseconds * 1e-9
        assert before <= value <= after

        node.set_parameters([Parameter("use_sim_time", value=True)])
        assert seconds.simulated
        node.get_clock().set_ros_time_override(Time(seconds=42, nanoseconds=5))
        assert seconds() == node.get_clock().now().nanoseconds * 1e-9 == 42_000_000_005 * 1e-9

        node.set_parameters([Parameter("use_sim_time", value=False)])
        assert not seconds.simulated
        assert abs(seconds() - time.time()) < 5.0
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_node_created_with_simulated_time_reads_it_from_the_start():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node(
        "ros_seconds_sim_test", context=context, parameter_overrides=[Parameter("use_sim_time", value=True)]
    )
    try:
        seconds = node_clock(node)
        assert seconds.simulated
        node.get_clock().set_ros_time_override(Time(seconds=7))
        assert seconds() == 7.0
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
