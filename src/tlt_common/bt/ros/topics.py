"""Topic data for behaviours: the latest message per topic, a condition on it, a copy of it to the
blackboard. Subscriptions are shared and their callbacks only store; a behaviour never waits."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import py_trees
from py_trees.common import Status
from rclpy.node import Node
from rclpy.qos import QoSProfile

from tlt_common.bt.nodes import Action, Condition
from tlt_common.bt.ros.clock import Clock, node_clock
from tlt_common.ros.direct_executor import QuickCallbackGroup


class TopicCache:
    """Latest message and its arrival time (on ``clock``, and on the wall clock for
    :mod:`tlt_common.ros.topic_silence_watch`) per topic, one subscription per topic.

    Several behaviours reading one topic share its subscription. Callbacks run on the executor's
    thread; readers get a (message, stamp) pair replaced atomically.
    """

    def __init__(self, node: Node, clock: Clock | None = None) -> None:
        self.node = node
        self.clock = clock or node_clock(node)
        self._latest: dict[str, tuple[Any, float] | None] = {}
        self._heard: dict[str, float] = {}  # time.monotonic() of the newest message, per topic
        self._subscriptions: dict[str, Any] = {}
        self._group = QuickCallbackGroup()  # a store never blocks: spun on the executor's own thread

    def watch(self, topic: str, msg_type: Any, qos: QoSProfile | int = 10) -> None:
        """Subscribe to ``topic`` once; later calls for the same topic are no-ops."""
        if topic in self._subscriptions:
            return
        self._latest[topic] = None

        def store(msg: Any, topic: str = topic) -> None:
            self._latest[topic] = (msg, self.clock())
            self._heard[topic] = time.monotonic()

        self._subscriptions[topic] = self.node.create_subscription(
            msg_type, topic, store, qos, callback_group=self._group
        )

    def latest(self, topic: str) -> tuple[Any, float] | None:
        """(message, arrival time) of the newest message on ``topic``, or None before the first."""
        return self._latest.get(topic)

    def topics(self) -> list[str]:
        """The topics watched, in the order they were first watched."""
        return list(self._subscriptions)

    def heard(self, topic: str) -> float | None:
        """``time.monotonic()`` when the newest message on ``topic`` arrived; None before the first."""
        return self._heard.get(topic)

    def publishers(self, topic: str) -> tuple[int, int]:
        """(publishers of ``topic`` this process's graph knows, those matched to its subscription)."""
        return self.node.count_publishers(topic), self._subscriptions[topic].get_publisher_count()

    def age(self, topic: str) -> float | None:
        """Seconds since the newest message on ``topic`` arrived; None before the first."""
        entry = self._latest.get(topic)
        return None if entry is None else self.clock() - entry[1]


class TopicCondition(Condition):
    """``predicate(latest message)`` on ``topic``.

    Reads: the topic (through ``cache``). Writes: nothing.
    SUCCESS when a message no older than ``max_age`` seconds exists and the predicate holds.
    FAILURE when the predicate is false, or the latest message is absent or stale (feedback says
    which). Never RUNNING.
    """

    def __init__(
        self,
        name: str,
        cache: TopicCache,
        topic: str,
        msg_type: Any,
        predicate: Callable[[Any], bool],
        *,
        max_age: float = 1.0,
        qos: QoSProfile | int = 10,
    ) -> None:
        super().__init__(name)
        self.cache = cache
        self.topic = topic
        self.predicate = predicate
        self.max_age = max_age
        cache.watch(topic, msg_type, qos)

    def evaluate(self) -> bool:
        entry = self.cache.latest(self.topic)
        if entry is None:
            self.feedback_message = f"no message on '{self.topic}' yet"
            return False
        msg, stamp = entry
        age = self.cache.clock() - stamp
        if age > self.max_age:
            self.feedback_message = (
                f"'{self.topic}' stale: last message {age:.2f} s old (max {self.max_age:g} s)"
            )
            return False
        ok = bool(self.predicate(msg))
        self.feedback_message = f"'{self.topic}': {'true' if ok else 'false'}"
        return ok


class TopicData(Action):
    """Copy the latest message on ``topic`` (or ``transform(message)``) to blackboard key ``key``.

    Reads: the topic (through ``cache``). Writes: ``key``.
    SUCCESS when a message no older than ``max_age`` seconds exists (it is written).
    RUNNING while none has arrived yet, for at most ``wait`` seconds from the start of the run.
    FAILURE when none arrived in ``wait`` seconds, or the latest is stale (nothing is written).
    """

    def __init__(
        self,
        name: str,
        cache: TopicCache,
        topic: str,
        msg_type: Any,
        key: str,
        *,
        transform: Callable[[Any], Any] | None = None,
        max_age: float = 1.0,
        wait: float = 0.0,
        qos: QoSProfile | int = 10,
    ) -> None:
        super().__init__(name)
        self.cache = cache
        self.topic = topic
        self.key = key
        self.transform = transform
        self.max_age = max_age
        self.wait = wait
        self._started = 0.0
        cache.watch(topic, msg_type, qos)
        self._bb = self.attach_blackboard_client(name=name)
        self._bb.register_key(key=key, access=py_trees.common.Access.WRITE)

    def initialise(self) -> None:
        self._started = self.cache.clock()

    def update(self) -> Status:
        entry = self.cache.latest(self.topic)
        now = self.cache.clock()
        if entry is None:
            if now - self._started < self.wait:
                self.feedback_message = f"waiting for '{self.topic}'"
                return Status.RUNNING
            return self.fail(f"no message on '{self.topic}'")
        msg, stamp = entry
        if now - stamp > self.max_age:
            return self.fail(
                f"'{self.topic}' stale: last message {now - stamp:.2f} s old (max {self.max_age:g} s)"
            )
        try:
            value = self.transform(msg) if self.transform is not None else msg
        except Exception as exc:
            return self.fail(f"cannot read '{self.topic}': {exc}")
        self._bb.set(self.key, value)
        self.feedback_message = f"{self.key} <- '{self.topic}'"
        return Status.SUCCESS


__all__ = ["TopicCache", "TopicCondition", "TopicData"]
