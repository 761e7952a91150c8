"""Spinning a node on rclpy's events executor, which waits and dispatches in C++.

rclpy's SingleThreadedExecutor rebuilds its wait set in Python on every wake-up, over every
subscription, timer, service and action the node holds; a driver node wakes a hundred times per
simulated second (its control cycle on ``/clock``, commands). The events executor
(``rclpy.experimental``, in Jazzy since rclpy 7.1) keeps its entities registered and runs a ready
callback directly: on the idle twin the six serial drivers went from 0.47 to 0.31 CPU seconds per
simulated second together, the UR drivers from 0.13 to 0.12 each (2026-11-26, two cores).

It is single-threaded: for nodes whose callbacks never wait on one another. Its ``spin_once``
without a timeout does not return when a signal shuts the context down (nor does ``rclpy.spin``
with it), so :func:`spin_events` waits at most :data:`WAKE_S` and checks the context in between.
"""

from __future__ import annotations

from rclpy.experimental import EventsExecutor
from rclpy.node import Node

# Longest wait for an event before the loop looks at the context again.
WAKE_S = 0.2


def spin_events(node: Node) -> None:
    """Spin ``node`` on an events executor until its context shuts down.

    Raises what a callback raises, and ``ExternalShutdownException`` or ``KeyboardInterrupt`` as
    ``rclpy.spin`` does when a signal stops it.
    """
    executor = EventsExecutor(context=node.context)
    executor.add_node(node)
    try:
        while node.context.ok():
            executor.spin_once(timeout_sec=WAKE_S)
    finally:
        executor.shutdown()


__all__ = ["WAKE_S", "spin_events"]
