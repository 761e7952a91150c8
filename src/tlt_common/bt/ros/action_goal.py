"""A behaviour that sends one goal to a ROS 2 action server and follows it to its result."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from action_msgs.msg import GoalStatus
from py_trees.common import Status
from rclpy.action import ActionClient
from rclpy.node import Node

from tlt_common.bt.ros.clients import shared_action_client
from tlt_common.bt.ros.clock import Clock
from tlt_common.bt.ros.remote_call import RemoteCall, default_result_ok


def default_feedback_text(feedback: Any) -> str:
    """``step`` (and ``progress`` as a percentage) when the feedback has them, else its repr."""
    step = getattr(feedback, "step", None)
    if step is None:
        return repr(feedback)
    progress = getattr(feedback, "progress", None)
    return f"{step} ({progress * 100:.0f}%)" if progress is not None else str(step)


_GOAL_STATUS_TEXT = {
    GoalStatus.STATUS_ABORTED: "aborted by the server",
    GoalStatus.STATUS_CANCELED: "canceled by the server",
    GoalStatus.STATUS_UNKNOWN: "ended in an unknown state",
}


class ActionGoal(RemoteCall):
    """Send one goal to a ROS 2 action server and follow it to its result.

    Reads: whatever ``goal`` (a callable) reads when it builds the goal at the start of a run.
    Writes: ``result_key`` (the result message) when given, on SUCCESS and on FAILURE from a result.
    ``feedback_message`` shows the server's latest feedback, or the reason of a failure.

    RUNNING: waiting for the server (up to ``server_timeout``), for acceptance, or for the result
    (up to ``result_timeout`` after acceptance).
    SUCCESS: the goal SUCCEEDED and ``result_ok(result)`` says it succeeded.
    FAILURE: server not available in time, goal rejected, result timeout (the goal is canceled),
    aborted or canceled by the server, or ``result_ok`` says it failed (its reason is reported).
    Pre-empted (terminate with INVALID): a goal in flight is canceled server-side.
    """

    server_kind = "action server"
    message_kind = "goal"

    def __init__(
        self,
        name: str,
        node: Node,
        action_type: Any,
        action_name: str,
        goal: Callable[[], Any] | Any,
        *,
        server_timeout: float = 5.0,
        result_timeout: float = 600.0,
        feedback_text: Callable[[Any], str] = default_feedback_text,
        result_ok: Callable[[Any], tuple[bool, str]] = default_result_ok,
        on_result: Callable[[Any, bool, str], None] | None = None,
        result_key: str | None = None,
        clock: Clock | None = None,
        client: ActionClient | None = None,
    ) -> None:
        super().__init__(
            name,
            node,
            client or shared_action_client(node, action_type, action_name),
            action_name,
            goal,
            server_timeout=server_timeout,
            answer_key=result_key,
            clock=clock,
        )
        self.result_timeout = result_timeout
        self.feedback_text = feedback_text
        self.result_ok = result_ok
        self.on_result = on_result
        self.last_result: Any = None
        self._reset()

    def _reset(self) -> None:
        self._started = 0.0
        self._accepted_at = 0.0
        self._send_future = None
        self._goal_handle = None
        self._result_future = None
        self._feedback: Any = None

    def initialise(self) -> None:
        self._reset()
        self._started = self.clock()
        self.last_result = None
        self.feedback_message = f"waiting for server '{self.server_name}'"

    def _on_feedback(self, message: Any) -> None:
        # Called on the executor's thread; a single assignment is atomic for the tick thread.
        self._feedback = message.feedback

    def send(self, message: Any) -> None:
        self._send_future = self.client.send_goal_async(message, feedback_callback=self._on_feedback)

    def update(self) -> Status:
        now = self.clock()
        if self._send_future is None:
            return self.send_when_ready(now)
        name = self.server_name
        if self._goal_handle is None:
            if not self._send_future.done():
                if now - self._started > self.server_timeout:
                    return self.fail(f"'{name}' did not answer the goal in {self.server_timeout:g} s")
                return Status.RUNNING
            handle = self._send_future.result()
            if handle is None or not handle.accepted:
                return self.fail(f"goal rejected by '{name}'")
            self._goal_handle = handle
            self._accepted_at = now
            self._result_future = handle.get_result_async()
            self.feedback_message = f"goal accepted by '{name}'"
        if not self._result_future.done():
            if self._feedback is not None:
                self.feedback_message = self.feedback_text(self._feedback)
            if now - self._accepted_at > self.result_timeout:
                self._cancel()
                return self.fail(f"no result from '{name}' within {self.result_timeout:g} s")
            return Status.RUNNING
        response = self._result_future.result()
        self._goal_handle = None
        status = response.status
        result = response.result
        self.last_result = result
        self.write_answer(result)
        if status != GoalStatus.STATUS_SUCCEEDED:
            reason = _GOAL_STATUS_TEXT.get(status, f"ended with goal status {status}")
            _, detail = self.result_ok(result)
            ok, reason = False, f"'{name}' {reason}" + (f": {detail}" if detail else "")
        else:
            ok, detail = self.result_ok(result)
            reason = "" if ok else f"'{name}' failed: {detail or 'no reason given'}"
        if self.on_result is not None:
            try:
                self.on_result(result, ok, reason)
            except Exception as exc:
                return self.fail(f"'{name}' result could not be recorded: {exc}")
        if not ok:
            return self.fail(reason)
        self.feedback_message = f"'{name}' succeeded"
        return Status.SUCCESS

    def _cancel(self) -> None:
        handle = self._goal_handle
        if handle is None and self._send_future is not None and self._send_future.done():
            # Accepted between two ticks: the handle exists but update() has not picked it up yet.
            accepted = self._send_future.result()
            handle = accepted if accepted is not None and accepted.accepted else None
            if handle is None:
                self._send_future = None
        if handle is not None:
            handle.cancel_goal_async()
        elif self._send_future is not None and not self._send_future.done():
            # Accepted later: cancel as soon as the handle exists, so no goal is left behind.
            def cancel_when_accepted(future: Any) -> None:
                accepted = future.result()
                if accepted is not None and accepted.accepted:
                    accepted.cancel_goal_async()

            self._send_future.add_done_callback(cancel_when_accepted)
        self._goal_handle = None
        self._send_future = None

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and (self._goal_handle is not None or self._send_future is not None):
            self._cancel()
            self.feedback_message = f"pre-empted: goal on '{self.server_name}' canceled"
        self._reset()


__all__ = ["ActionGoal", "default_feedback_text"]
