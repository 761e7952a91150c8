"""A behaviour that calls a ROS 2 service once per run and waits, by polling, for its response."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from py_trees.common import Status
from rclpy.node import Node

from tlt_common.bt.ros.clients import shared_service_client
from tlt_common.bt.ros.clock import Clock
from tlt_common.bt.ros.remote_call import RemoteCall, default_result_ok


class ServiceCall(RemoteCall):
    """Call a ROS 2 service once per run and wait (by polling) for its response.

    Reads: whatever ``request`` (a callable) reads when it builds the request.
    Writes: ``response_key`` (the response message) when given.
    RUNNING: waiting for the service (up to ``service_timeout``) or the response (up to ``timeout``).
    SUCCESS: a response came and ``response_ok(response)`` says it is good.
    FAILURE: service not available, no response in time (the request is dropped), the request
    could not be built, or ``response_ok`` says it failed (its reason is reported).
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

    def initialise(self) -> None:
        self._future = None
        self._started = self.clock()
        self.last_response = None
        self.feedback_message = f"waiting for service '{self.server_name}'"

    def send(self, message: Any) -> None:
        self._future = self.client.call_async(message)

    def update(self) -> Status:
        now = self.clock()
        if self._future is None:
            return self.send_when_ready(now)
        if not self._future.done():
            if now - self._started > self.timeout:
                self._drop()
                return self.fail(f"no response from '{self.server_name}' within {self.timeout:g} s")
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
