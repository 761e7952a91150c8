"""An rclpy ``Node`` whose publishers and subscriptions carry no QoS-event handlers unless asked.

rclpy gives every publisher and subscription two default event handlers (incompatible QoS,
incompatible type), each a waitable that the executor enters, counts, adds and polls every time
it builds its wait set, that is, on every message and timer. In the CRS's node, with some hundred of
them, that bookkeeping is most of its CPU, and the whole system on the twin runs measurably
slower with them. The handlers only log a warning on a
misconfiguration that this project's fixed QoS profiles do not produce.

:class:`LeanNode` passes ``use_default_callbacks=False`` when a caller gives no
``event_callbacks``; callbacks a caller asks for are kept. Set ``TLT_QOS_EVENTS=1`` in the
environment to get rclpy's default handlers back (and their warnings) when chasing a topic that
stays silent.
"""

from __future__ import annotations

import os
from typing import Any

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node

QOS_EVENTS_ENV = "TLT_QOS_EVENTS"


def default_handlers_wanted() -> bool:
    """Whether ``TLT_QOS_EVENTS`` asks for rclpy's default QoS-event handlers."""
    return os.environ.get(QOS_EVENTS_ENV, "").strip().lower() in ("1", "true", "yes", "on")


class LeanNode(Node):
    """``rclpy.node.Node`` without default QoS-event handlers (see the module docstring)."""

    def create_publisher(
        self, *args: Any, event_callbacks: PublisherEventCallbacks | None = None, **kwargs: Any
    ):
        if event_callbacks is None and not default_handlers_wanted():
            event_callbacks = PublisherEventCallbacks(use_default_callbacks=False)
        return super().create_publisher(*args, event_callbacks=event_callbacks, **kwargs)

    def create_subscription(
        self, *args: Any, event_callbacks: SubscriptionEventCallbacks | None = None, **kwargs: Any
    ):
        if event_callbacks is None and not default_handlers_wanted():
            event_callbacks = SubscriptionEventCallbacks(use_default_callbacks=False)
        return super().create_subscription(*args, event_callbacks=event_callbacks, **kwargs)


__all__ = ["QOS_EVENTS_ENV", "LeanNode", "default_handlers_wanted"]
