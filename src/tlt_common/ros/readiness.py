"""A process's readiness on a latched topic, for the processes that depend on it.

The message is ``diagnostic_msgs/DiagnosticStatus``: level ``OK`` and message ``ready`` when the
process can serve, ``WARN`` and the reason while it cannot (vision until it has heard the joint
states that place its cameras). It is published when the reason changes, reliable and transient
local with depth 1, so a subscriber that joins later still gets the last word. A server that is
up in the graph may not be able to answer yet: the CRS refuses Start until vision says ready, so
that the first request does not meet "no joint state for ur_x_shoulder_pan_joint yet".

:class:`ReadinessWatch` is the other side, for a caller that must know when the process came back:
every word it hears is counted, and since a process says a reason only when it changes (and says
ready at most once), a word heard after a request went out means the process was restarted (a new
one says its word as it starts) or its readiness changed. Either way the request may never be
answered, and once the process says ready again it is worth asking again
(:class:`tlt_common.bt.ros.ServiceCall` with ``server_state``).
"""

from __future__ import annotations

import threading

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from tlt_common.ros.direct_executor import QuickCallbackGroup

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


class ReadinessWatch:
    """The words heard on a readiness ``topic`` (see the module docstring): how many, and the last."""

    def __init__(self, node: Node, topic: str) -> None:
        self.topic = topic
        self._last: DiagnosticStatus | None = None
        self._heard = 0
        self._lock = threading.Lock()
        # Storing only: spun on an executor's own thread, never behind a blocked callback.
        self._subscription = node.create_subscription(
            DiagnosticStatus, topic, self._store, LATCHED, callback_group=QuickCallbackGroup()
        )

    def _store(self, status: DiagnosticStatus) -> None:
        with self._lock:
            self._last = status
            self._heard += 1

    def heard(self) -> int:
        """How many words were heard so far: one more than before means a new word."""
        with self._lock:
            return self._heard

    def not_ready(self) -> str:
        """Why the process cannot serve, by its last word ('' when it can)."""
        with self._lock:
            return not_ready_reason(self._last)


def not_ready_reason(status: DiagnosticStatus | None) -> str:
    """Why the process whose ``status`` this is cannot serve ('' when it can); ``None``, nothing
    heard from it yet."""
    if status is None:
        return "has not said it is ready"
    if status.level == DiagnosticStatus.OK:
        return ""
    return status.message or "not ready"


__all__ = ["LATCHED", "ReadinessPublisher", "ReadinessWatch", "not_ready_reason"]
