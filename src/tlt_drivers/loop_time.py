"""The time base of a driver node's control loop: its timers, trajectory time and link watchdogs.

On the twin (``use_sim_time``) the loop runs on sim time, which stands still while the twin waits
for a late driver. The far end (the twin's emulators) is on sim time too, so a link watchdog must
count in the same time base, or every pause of the simulation would look like a dead link.

On hardware it runs on the monotonic clock, not on ROS time: there ROS time is the system clock,
which NTP or an operator can set back, and an rcl timer on it then waits until the clock is back
where it was (ros2/rclpy#1490). Every stream a far-end watchdog guards (the lifter firmware's
40 ms, the UR's RTDE) would stop for as long as the step. Message stamps stay on ROS time.

``use_sim_time`` is read once, when the loop is made.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.timer import Timer


def _on_sim_time(node: Node) -> bool:
    return bool(node.get_parameter("use_sim_time").value)


def loop_clock(node: Node) -> Callable[[], float]:
    """Seconds in the time base of ``node``'s loop: ROS time under sim time, else monotonic."""
    if _on_sim_time(node):
        clock = node.get_clock()
        return lambda: clock.now().nanoseconds * 1e-9
    return time.monotonic


def create_loop_timer(node: Node, period_s: float, callback: Callable[[], None]) -> Timer:
    """A timer of ``node`` in its loop's time base (the steady clock is ``time.monotonic``'s)."""
    clock = node.get_clock() if _on_sim_time(node) else Clock(clock_type=ClockType.STEADY_TIME)
    return node.create_timer(period_s, callback, clock=clock)


__all__ = ["create_loop_timer", "loop_clock"]
