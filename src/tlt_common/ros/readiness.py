"""A process's readiness on a latched topic, for the processes that depend on it.

The message is ``diagnostic_msgs/DiagnosticStatus``: level ``OK`` and message ``ready`` when the
process can serve, ``WARN`` and the reason while it cannot (vision until it has heard the joint
states that place its cameras). It is published when the reason changes, reliable and transient
local with depth 1, so a subscriber that joins later still gets the last word. A server that is
up in the graph may not be able to answer yet: the CRS refuses Start until vision says ready, so
that the first request does not meet "no joint state for ur_x_shoulder_pan_joint yet".
"""

from __future__ import annotations

import threading

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


class ReadinessPublisher:
    """Publishes ``name``'s readiness on ``topic`` each time :meth:`say` gets a new reason."""

    def __init__(self, node: Node, topic: str, name: str) -> None:
        self._publisher = node.create_publisher(DiagnosticStatus, topic, LATCHED)
        self._name = name
        self._lock = threading.Lock()
        self._said: str | None = None

    @property
    def ready(self) -> bool:
        return self._said == ""

    def say(self, not_ready: str) -> None:
        """Publish why the process is not ready (``''``: it is), unless that is what it said last."""
        with self._lock:
            if not_ready == self._said:
                return
            self._said = not_ready
            self._publisher.publish(
                DiagnosticStatus(
                    level=DiagnosticStatus.WARN if not_ready else DiagnosticStatus.OK,
                    name=self._name,
                    message=not_ready or "ready",
                )
            )


def not_ready_reason(status: DiagnosticStatus | None) -> str:
    """Why the process whose ``status`` this is cannot serve ('' when it can); ``None``, nothing
    heard from it yet."""
    if status is None:
        return "has not said it is ready"
    if status.level == DiagnosticStatus.OK:
        return ""
    return status.message or "not ready"


__all__ = ["LATCHED", "ReadinessPublisher", "not_ready_reason"]
