"""Say so when a node stops hearing a topic it cannot work without, and whether DDS still sees the
topic's publisher.

An ARS whose arm's joint states stop coming fails every request on "no fresh joint state", and
nothing says why the states stopped: the driver is down, or it publishes and this process no longer
receives it. After a network cut heals, Fast DDS can rediscover a participant without matching its
endpoints again (docs/deployment.md): the publisher is in this process's graph, yet matched to none
of its subscriptions. :class:`TopicSilenceWatch` is a thread on the wall clock, outside the
executor, that logs a warning when a watched topic of a :class:`HeardTopics` (such as
:class:`~tlt_common.bt.ros.TopicCache`) has been silent for ``stall_s`` seconds of wall time,
naming how many publishers the graph knows and how many are matched to the subscription, again
every ``repeat_s`` seconds while it stays silent (what DDS sees changes when a cut link heals), and
a note when the topic is heard again.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from typing import Protocol

from tlt_common.ros.watch_thread import WatchThread

_log = logging.getLogger("tlt.topic_silence")


class HeardTopics(Protocol):
    """What the watch asks of the subscriptions it watches. ``tlt_common.bt.ros.TopicCache`` is
    one; a protocol rather than that class, as the behaviour trees' ROS package imports this one."""

    def topics(self) -> list[str]:
        """The topics subscribed to."""
        ...

    def heard(self, topic: str) -> float | None:
        """``time.monotonic()`` when the newest message on ``topic`` arrived; None before the first."""
        ...

    def publishers(self, topic: str) -> tuple[int, int]:
        """(publishers of ``topic`` this process's graph knows, those matched to its subscription)."""
        ...


class TopicSilenceWatch(WatchThread):
    """Watch ``topics`` of ``cache``; ``silences`` lists (topic, graph publishers, matched) reported."""

    def __init__(self, cache: HeardTopics, topics: Sequence[str], name: str, stall_s: float = 10.0,
                 repeat_s: float = 30.0, period_s: float = 1.0) -> None:  # fmt: skip
        unknown = [t for t in topics if t not in cache.topics()]
        if unknown:
            raise ValueError(f"{name}: not watched by the topic cache: {', '.join(unknown)}")
        super().__init__(name, "topic-silence", period_s)
        self.cache = cache
        self.topics = list(topics)
        self.stall_s = stall_s
        self.repeat_s = repeat_s
        self.silences: list[tuple[str, int, int]] = []

    def _run(self) -> None:
        started = time.monotonic()
        silent: dict[str, tuple[float, float]] = {}  # topic -> (last message, last report), wall time
        while self._next_period():
            now = time.monotonic()
            for topic in self.topics:
                heard = self.cache.heard(topic)
                since = started if heard is None else heard
                if topic in silent:
                    if heard is not None and heard != silent[topic][0]:
                        _log.warning("%s: '%s' heard again after %.0f s of wall time", self.name, topic,
                                     heard - silent.pop(topic)[0])  # fmt: skip
                        continue
                    if now - silent[topic][1] < self.repeat_s:
                        continue
                elif now - since < self.stall_s:
                    continue
                try:
                    known, matched = self.cache.publishers(topic)
                except Exception:  # the node is being destroyed: nothing left to watch
                    return
                silent[topic] = (since, now)
                self.silences.append((topic, known, matched))
                _log.warning(
                    "%s: nothing on '%s' for %.0f s of wall time; publishers: %d in this process's graph, "
                    "%d matched to its subscription%s",
                    self.name,
                    topic,
                    now - since,
                    known,
                    matched,
                    " (DDS sees the publisher but has not matched it: a rediscovery after a network cut "
                    "that did not rematch the endpoints)"
                    if known > matched
                    else "",
                )


__all__ = ["HeardTopics", "TopicSilenceWatch"]
