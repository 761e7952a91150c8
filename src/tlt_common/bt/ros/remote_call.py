"""What a behaviour sending one goal or request to a ROS 2 server per run shares with the others.

:class:`RemoteCall` is the base of :class:`~tlt_common.bt.ros.action_goal.ActionGoal` and
:class:`~tlt_common.bt.ros.service_call.ServiceCall`: the shared client's readiness, the wait for
the server, building the message when it is sent, the clock its limits are measured on, and the
blackboard key its answer is written to.

Whether a server is there is read through :mod:`tlt_common.bt.server_readiness`: a behaviour waits
on an answer up to a quarter second old and sends, or fails for want of a server, only on a fresh
one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import py_trees
from py_trees.common import Status
from rclpy.node import Node

from tlt_common.bt.nodes import Action
from tlt_common.bt.ros.clock import Clock, node_clock
from tlt_common.bt.server_readiness import readiness_of


def default_result_ok(result: Any) -> tuple[bool, str]:
    """A result with ``success`` or ``accepted`` and ``reason`` fields (the TLT interfaces) decides by
    them; any other result counts as success."""
    for field in ("success", "accepted"):
        if hasattr(result, field):
            return bool(getattr(result, field)), str(getattr(result, "reason", "") or "")
    return True, ""


class RemoteCall(Action):
    """Base of the behaviours that send one message (a goal, a request) to a ROS 2 server per run.

    Reads: whatever ``message`` (a callable, or the message itself) reads when it builds the
    message, at the moment it is sent.
    Writes: ``answer_key`` (the answer message) when given, through :meth:`write_answer`.
    RUNNING: waiting for the server, up to ``server_timeout`` seconds on ``clock`` from the start
    of the run (:meth:`send_when_ready`, while nothing is sent yet).
    FAILURE: the server is not there after ``server_timeout`` (judged on a fresh answer), or the
    message could not be built (the exception is reported).
    What follows the sending (RUNNING, SUCCESS, FAILURE on the answer) is the subclass's: its
    ``update()`` calls :meth:`send_when_ready` until :meth:`send` was called, and follows the
    answer after.

    ``server_kind`` and ``message_kind`` name the server and the message in feedback messages.
    """

    server_kind: ClassVar[str] = "server"
    message_kind: ClassVar[str] = "message"

    def __init__(
        self,
        name: str,
        node: Node,
        client: Any,
        server_name: str,
        message: Callable[[], Any] | Any,
        *,
        server_timeout: float,
        answer_key: str | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(name)
        self.node = node
        self.client = client
        self.server_name = server_name
        self.server_timeout = server_timeout
        self.clock = clock or node_clock(node)
        self._readiness = readiness_of(client)  # one per client: every behaviour on it shares it
        self._message = message
        self._started = 0.0  # start of the wait for the server, then of the wait for the answer
        self.answer_key = answer_key
        self._bb = None
        if answer_key:
            self._bb = self.attach_blackboard_client(name=name)
            self._bb.register_key(key=answer_key, access=py_trees.common.Access.WRITE)

    def send(self, message: Any) -> None:
        """Send ``message`` to the server (asynchronously: a behaviour never waits). Each kind of
        call sends its own way: :class:`ActionGoal` a goal, :class:`ServiceCall` a request."""
        raise NotImplementedError(f"{type(self).__name__} does not say how it sends")

    def send_when_ready(self, now: float) -> Status:
        """Wait for the server; once a fresh answer says it is up, build the message and
        :meth:`send` it (RUNNING). FAILURE when the server is not there after ``server_timeout``
        or the message cannot be built."""
        up = self._readiness.wait(now - self._started, self.server_timeout)
        if up is None:
            return Status.RUNNING
        if not up:
            return self.fail(
                f"{self.server_kind} '{self.server_name}' not available after {self.server_timeout:g} s"
            )
        try:
            message = self._message() if callable(self._message) else self._message
        except Exception as exc:
            return self.fail(f"cannot build {self.message_kind} for '{self.server_name}': {exc}")
        self.send(message)
        self._started = now
        self.feedback_message = f"{self.message_kind} sent to '{self.server_name}'"
        return Status.RUNNING

    def write_answer(self, answer: Any) -> None:
        """Write ``answer`` to ``answer_key`` on the blackboard, when one was given."""
        if self._bb is not None and self.answer_key is not None:
            self._bb.set(self.answer_key, answer)


__all__ = ["RemoteCall", "default_result_ok"]
