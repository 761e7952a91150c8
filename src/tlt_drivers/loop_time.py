"""The time base of a driver node's control loop: its trajectories and link watchdogs.

On the twin (``use_sim_time``) the loop runs on sim time, which stands still while the twin waits
for a late driver. The far end (the twin's emulators) is on sim time too, so a link watchdog must
count in the same time base, or every pause of the simulation would look like a dead link. On
hardware it is the monotonic clock, as the loop's timer is (``tlt_common.ros.periodic_timer``: a
system clock set back must not stop a stream that a watchdog at the far end guards).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.node import Node

from tlt_common.ros.periodic_timer import runs_on_sim_time


def loop_clock(node: Node) -> Callable[[], float]:
    """Seconds in the time base of ``node``'s loop: ROS time under sim time, else monotonic."""
    if runs_on_sim_time(node):
        clock = node.get_clock()
        return lambda: clock.now().nanoseconds * 1e-9
    return time.monotonic


__all__ = ["loop_clock"]
