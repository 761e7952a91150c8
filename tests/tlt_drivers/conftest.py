"""Fixtures shared by the driver tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from rclpy.clock import ROSClock
from rclpy.node import Node


@pytest.fixture
def stop_ros_time() -> Iterator[Callable[[Node], None]]:
    """``stop_ros_time(node)``: from now on ``node``'s ROS time stands still, as the system clock
    seems to a timer on it after it was set back (a test cannot set the machine's clock back).
    ROS time runs again after the test."""
    stopped: list[ROSClock] = []

    def stop(node: Node) -> None:
        clock = node.get_clock()
        now = clock.now()
        clock._set_ros_time_is_active(True)
        clock.set_ros_time_override(now)
        stopped.append(clock)

    yield stop
    for clock in stopped:
        clock._set_ros_time_is_active(False)
