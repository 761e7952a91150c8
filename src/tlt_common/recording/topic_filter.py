"""Which topics a recording takes: an optional allow-list, exclusion patterns, images left out.

A topic is recorded when it is on the allow-list (or there is none) and matches no exclusion
pattern. Rendered camera images would dominate a recording, so unless images are asked for, image
topics are excluded too, except those named on the allow-list. An image topic is one whose type is
in :data:`IMAGE_TYPES` (the twin publishes its images as ``/cameras/<camera>/rgb``, ``/depth`` and
``/segmentation``) or whose name matches :data:`IMAGE_PATTERN` (the usual ROS names).
Patterns are Python regular expressions matched against the whole topic name.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

IMAGE_PATTERN = r".*/image(_raw)?$|.*/depth$"
IMAGE_TYPES = frozenset({"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"})


class TopicFilter:
    """Decides per topic name; raises ``ValueError`` naming a pattern that does not compile."""

    def __init__(
        self,
        topics: Iterable[str] | None = None,
        exclude: Iterable[str] = (),
        include_images: bool = False,
    ) -> None:
        self.topics = None if topics is None else frozenset(topics)
        self._exclude = [_compile(p) for p in exclude]
        self._images = None if include_images else _compile(IMAGE_PATTERN)

    def accepts(self, topic: str, type_name: str | None = None) -> bool:
        """Whether to record ``topic``; ``type_name`` (``pkg/msg/Type``) when known."""
        if self.topics is not None and topic not in self.topics:
            return False
        if any(p.fullmatch(topic) for p in self._exclude):
            return False
        # An allow-list names its topics on purpose, images included.
        if self._images is None or self.topics is not None:
            return True
        return not (self._images.fullmatch(topic) or type_name in IMAGE_TYPES)


def _compile(pattern: str) -> re.Pattern[str]:
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise ValueError(f"exclude pattern {pattern!r} is not a regular expression: {exc}") from None
