"""Seconds on a node's clock, the time base of the ROS behaviours' time limits.

By default the node's clock is ROS time, so a twin publishing ``/clock`` faster than real time
shortens every limit accordingly.
"""

from __future__ import annotations

import time
import weakref
from collections.abc import Callable
from typing import Any

from rclpy.clock import ClockChange, JumpThreshold, ROSClock, TimeJump
from rclpy.node import Node

Clock = Callable[[], float]


class RosSeconds:
    """Seconds on an rclpy ROS clock, read cheaply while no simulated time is active.

    rclpy's ``Clock.now()`` builds a ``Time`` on every call (several microseconds, as much as a
    whole bare behaviour tick). While ROS time is not overridden by ``/clock``, rcl answers it from
    the system clock (CLOCK_REALTIME), which ``time.time_ns()`` reads directly. A jump callback on
    clock change (the public rclpy way to hear of it) says when simulated time is switched on or
    off; from then on ``Clock.now()`` is used again.
    """

    def __init__(self, clock: ROSClock) -> None:
        self._clock_now = clock.now
        # The callback holds only this cell, not self: the clock keeps its jump callbacks alive.
        self._simulated = simulated = [False]

        def on_jump(jump: TimeJump) -> None:
            if jump.clock_change == ClockChange.ROS_TIME_ACTIVATED:
                simulated[0] = True
            elif jump.clock_change == ClockChange.ROS_TIME_DEACTIVATED:
                simulated[0] = False

        handle = clock.create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=None, on_clock_change=True), post_callback=on_jump
        )
        # The clock holds the handle and the handle the clock: unregister once nobody reads these
        # seconds any more, so neither is kept for the life of the process.
        finalizer = weakref.finalize(self, _unregister, handle)
        finalizer.atexit = False
        # Read after registering, so a switch in between is not missed.
        simulated[0] = clock.ros_time_is_active

    @property
    def simulated(self) -> bool:
        """Whether ROS time is currently overridden (``use_sim_time`` and ``/clock``)."""
        return self._simulated[0]

    def __call__(self) -> float:
        if self._simulated[0]:
            return self._clock_now().nanoseconds * 1e-9
        return time.time_ns() * 1e-9


def _unregister(handle: Any) -> None:
    try:
        handle.unregister()
    except Exception:  # the clock's handle is already gone: nothing left to unregister
        pass


def node_clock(node: Node) -> Clock:
    """Seconds on ``node``'s clock (ROS time; simulated time when use_sim_time is set)."""
    clock = node.get_clock()
    if isinstance(clock, ROSClock):
        return RosSeconds(clock)
    return lambda: clock.now().nanoseconds * 1e-9


__all__ = ["Clock", "RosSeconds", "node_clock"]
