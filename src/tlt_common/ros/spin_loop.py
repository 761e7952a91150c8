"""A spin loop that survives an entity destroyed while the executor builds its wait set.

rclpy's ``Executor.spin`` dies, and every callback with it, when a subscription, client or action
client is destroyed by another thread while the executor adds it to a wait set (``InvalidHandle``,
or ``RCLError`` "... pointer is invalid"). The next wait set is built from the entities that are
left, so the loop carries on.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import rclpy
import rclpy.executors
from rclpy._rclpy_pybind11 import InvalidHandle, RCLError


def spin(executor: Any, context: Any = None, stop: Callable[[], bool] | None = None) -> None:
    """Spin ``executor`` until its context shuts down or ``stop()`` is true."""
    while rclpy.ok(context=context) and not (stop is not None and stop()):
        try:
            executor.spin_once(timeout_sec=0.2)
        except (InvalidHandle, RCLError):
            continue


def spin_node(node: Any, stop: Callable[[], bool]) -> None:
    """Spin ``node`` alone on a single-threaded executor until ``stop()`` or its context ends,
    then destroy it and shut rclpy down: the whole life of a one-node process."""
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    try:
        spin(executor, node.context, stop)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


__all__ = ["spin", "spin_node"]
