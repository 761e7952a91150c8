"""An rclpy ActionClient that may send goals from a thread other than the executor's."""

from __future__ import annotations

import threading
from typing import Any

from rclpy.action import ActionClient


class SerialisedActionClient(ActionClient):
    """An ActionClient safe to use from a thread other than the executor's.

    rclpy's ActionClient sends a goal (cancel, result) request and only then registers the future
    waiting for its response. When a tree ticks in one thread and the executor takes responses in
    another, a fast server's response can be taken in between and is dropped ("Ignoring unexpected
    goal response"), leaving the behaviour waiting for an answer that already came. Sending and
    taking are serialised here, so a response is taken only once its request is registered.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        # Before the base class adds this client to its node: an executor already spinning that
        # node may take data from it at once (its spin thread would die on the missing lock).
        self._serial = threading.RLock()
        super().__init__(*args, **kwargs)

    def send_goal_async(self, *args: Any, **kwargs: Any) -> Any:
        with self._serial:
            return super().send_goal_async(*args, **kwargs)

    def _cancel_goal_async(self, goal_handle: Any) -> Any:
        with self._serial:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle: Any) -> Any:
        with self._serial:
            return super()._get_result_async(goal_handle)

    def take_data(self) -> Any:
        with self._serial:
            return super().take_data()
