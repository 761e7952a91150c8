"""The time base of a driver node's control loop, for the watchdogs on its link.

A driver's control cycle is a ROS timer: on the twin (``use_sim_time``) it runs on sim time, which
stands still while the twin waits for a late driver. The far end (the twin's emulators) is on sim
time too, so a link watchdog must count in the same time base, or every pause of the simulation
would look like a dead link. On hardware (no sim time) it is the monotonic clock.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.node import Node


def loop_clock(node: Node) -> Callable[[], float]:
    """Seconds in the time base of ``node``'s timers: ROS time under sim time, else monotonic."""
    if node.get_parameter("use_sim_time").value:
        clock = node.get_clock()
        return lambda: clock.now().nanoseconds * 1e-9
    return time.monotonic


__all__ = ["loop_clock"]
