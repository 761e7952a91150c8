"""Destroy an rclpy node so that nothing of it stays in the ROS graph.

rclpy 7.1 (Jazzy) ``Node.destroy_node`` destroys publishers, subscriptions, services, clients and
timers, but not waitables: an action server or client outlives it, and holds the rcl node, and so
the context's DDS participant, until the garbage collector gets to it. Such a participant goes on
announcing its endpoints after ``rclpy.shutdown``: a process that starts nodes one after another
(a test session, a restarted agent in one process) then sees the old servers next to the new ones,
which kept probes from discovering the new servers and goals from being answered.
"""

from __future__ import annotations

from typing import Any


def destroy_node(node: Any) -> None:
    """Destroy ``node``'s action servers and clients, then the node. Stop its executor first."""
    for waitable in list(node.waitables):
        destroy = getattr(waitable, "destroy", None)
        if destroy is not None:
            destroy()
    node.destroy_node()


__all__ = ["destroy_node"]
