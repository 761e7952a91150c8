"""Periodic timers that follow sim time on the twin and the monotonic clock on hardware.

rclpy's timers run on the node's ROS time by default. Under the twin (``use_sim_time``) that is
what periodic work must follow: sim time stands still while the twin waits, and runs faster than
real time when it can. On hardware ROS time is the system clock, which chrony or an operator can
set back, and an rcl timer on it then waits until the clock is back where it was
(ros2/rclpy#1490): a driver's stream to a watchdog (the lifter firmware's 40 ms, the UR's RTDE),
the trees' ticks and the ground telemetry would all stop for as long as the step. On the steady
clock they go on. Message stamps stay on ROS time.

``use_sim_time`` is read when the timer is made.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.timer import Timer


def runs_on_sim_time(node: Node) -> bool:
    """Whether ``node`` has ``use_sim_time`` set."""
    return bool(node.get_parameter("use_sim_time").value)


def create_periodic_timer(node: Node, period_s: float, callback: Callable[[], Any], **kwargs: Any) -> Timer:
    """``node.create_timer`` on sim time under the twin, else on the steady clock
    (``time.monotonic``'s); ``kwargs`` (``callback_group``) go to ``create_timer``."""
    clock = node.get_clock() if runs_on_sim_time(node) else Clock(clock_type=ClockType.STEADY_TIME)
    return node.create_timer(period_s, callback, clock=clock, **kwargs)


__all__ = ["create_periodic_timer", "runs_on_sim_time"]
