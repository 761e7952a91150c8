"""A behaviour that calls a ROS 2 service once per run and waits, by polling, for its response.

A request can go unanswered because the server's process died with it: the launcher restarts the
process, and the new one never heard the request. Given ``retries`` and the server's readiness
(``server_state``, a :class:`tlt_common.ros.readiness.ReadinessWatch` on the process's latched
status), such a request is asked again once the process is back, instead of failing: a word on the
status heard after the request went out (a restarted process says one as it starts), or no
response within ``timeout``, gives the request up; then, once a new word says ready (within
``back_within``), the same request is sent again, at most ``retries`` times per run.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from py_trees.common import Status
from rclpy.node import Node

from tlt_common.bt.ros.clients import shared_service_client
from tlt_common.bt.ros.clock import Clock
from tlt_common.bt.ros.remote_call import RemoteCall, default_result_ok


class ServerState(Protocol):
    """A server process's readiness as :class:`tlt_common.ros.readiness.ReadinessWatch` gives it."""

    def heard(self) -> int: ...

    def not_ready(self) -> str: ...


class ServiceCall(RemoteCall):
    """Call a ROS 2 service once per run and wait (by polling) for its response.

    Reads: whatever ``request`` (a callable) reads when it builds the request.
    Writes: ``response_key`` (the response message) when given.
    RUNNING: waiting for the service (up to ``service_timeout``) or the response (up to ``timeout``).
    SUCCESS: a response came and ``response_ok(response)`` says it is good.
    FAILURE: service not available, no response in time (the request is dropped), the request
    could not be built, or ``response_ok`` says it failed (its reason is reported).
    With ``retries`` and ``server_state`` (module docstring): RUNNING while a request given up
    waits for the server's process to come back (up to ``back_within``) and is sent again;
    FAILURE once ``retries`` requests were given up, or the process did not come back in time.
    """

    server_kind = "service"
    message_kind = "request"

    def __init__(
        self,
        name: str,
        node: Node,
        srv_type: Any,
        srv_name: str,
        request: Callable[[], Any] | Any,
        *,
        service_timeout: float = 5.0,
        timeout: float = 30.0,
        response_ok: Callable[[Any], tuple[bool, str]] = default_result_ok,
        response_key: str | None = None,
        clock: Clock | None = None,
        retries: int = 0,
        server_state: ServerState | None = None,
        back_within: float = 60.0,
    ) -> None:
        super().__init__(
            name,
            node,
            shared_service_client(node, srv_type, srv_name),
            srv_name,
            request,
            server_timeout=service_timeout,
            answer_key=response_key,
            clock=clock,
        )
        self.timeout = timeout
        self.response_ok = response_ok
        self.last_response: Any = None
        self._future = None
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self.retries = retries
        self.server_state = server_state
        self.back_within = back_within
        self._tries = 0  # requests given up in this run
        self._lost = ""  # why the last request was given up, while waiting to ask again
        self._heard_at_send = 0

    def initialise(self) -> None:
        self._future = None
        self._started = self.clock()
        self.last_response = None
        self._tries, self._lost = 0, ""
        self.feedback_message = f"waiting for service '{self.server_name}'"

    def send(self, message: Any) -> None:
        if self.server_state is not None:
            self._heard_at_send = self.server_state.heard()
        self._future = self.client.call_async(message)

    def update(self) -> Status:
        now = self.clock()
        if self._future is None:
            if self._lost:
                return self._wait_until_back(now)
            return self.send_when_ready(now)
        if not self._future.done():
            lost = self._why_lost(now)
            if not lost:
                return Status.RUNNING
            self._drop()
            if self._tries >= self.retries:
                return self.fail(lost + (f" (asked {self._tries + 1} times)" if self._tries else ""))
            self._tries += 1
            self._lost, self._started = lost, now
            self.feedback_message = f"{lost}; asking again once it is back ({self._tries} of {self.retries})"
            return Status.RUNNING
        response = self._future.result()
        self._future = None
        self.last_response = response
        self.write_answer(response)
        ok, reason = self.response_ok(response)
        if not ok:
            return self.fail(f"'{self.server_name}' refused: {reason or 'no reason given'}")
        self.feedback_message = f"'{self.server_name}' answered"
        return Status.SUCCESS

    def _why_lost(self, now: float) -> str:
        """Why the request out is given up ('' while it is not): the server's process said a new
        word since it went out (only counted where it may be asked again, and where a word was
        heard before: the first one can reach a caller that has just subscribed after its first
        request), or no response came within ``timeout``."""
        state, before = self.server_state, self._heard_at_send
        if self.retries and state is not None and before and state.heard() != before:
            return f"no response from '{self.server_name}', whose process restarted or changed its readiness"
        if now - self._started > self.timeout:
            return f"no response from '{self.server_name}' within {self.timeout:g} s"
        return ""

    def _wait_until_back(self, now: float) -> Status:
        """After a request was given up: RUNNING until the server's process says a new word, and
        that word is ready (then the request goes out again when the service is up); FAILURE
        when that takes longer than ``back_within``."""
        state = self.server_state
        if state is not None:
            renewed = state.heard() != self._heard_at_send
            why = state.not_ready() if renewed else "no word from its process since the request went out"
            if why:
                if now - self._started > self.back_within:
                    return self.fail(f"{self._lost}; not back within {self.back_within:g} s ({why})")
                self.feedback_message = f"{self._lost}; waiting for it to come back: {why}"
                return Status.RUNNING
        self._lost = ""
        self._started = now
        return self.send_when_ready(now)

    def postpone(self, seconds: float) -> None:
        """Leave ``seconds`` (a pause it was left running through) out of its time limits."""
        self._started += seconds

    def _drop(self) -> None:
        if self._future is not None:
            self.client.remove_pending_request(self._future)
            self._future.cancel()
            self._future = None

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID:
            self._drop()
        self._future = None


__all__ = ["ServiceCall"]
