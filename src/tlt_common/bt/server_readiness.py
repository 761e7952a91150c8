"""Whether a ROS 2 action or service server is up, without asking rclpy on every tick.

rclpy answers ``server_is_ready()`` / ``service_is_ready()`` with a query of the ROS graph (4-5 µs
here, about a bare py_trees leaf's whole tick). A behaviour waiting for a server that is not there
asked it on every tick, and a behaviour following a goal asked it on every tick to notice the
server going away. :class:`Readiness` keeps the answer for ``period`` seconds of monotonic time
(wall time, so a fast simulated clock does not make it ask more often), shared by every behaviour
using the same client. At the CRS's 10 Hz a waiting behaviour asks on about every third tick.

Rule for callers: *wait* on :meth:`Readiness.ready` (a cached answer), *act* on
:meth:`Readiness.ready_now` (a fresh one): a goal is sent, and a "server not available" or
"server gone" failure is raised, only on an answer rclpy has just given. A cached answer only
delays noticing that a server came or went, by at most ``period``; it never decides anything.
:meth:`Readiness.wait` is that rule for a behaviour waiting to send its goal or request.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

READINESS_PERIOD_S = 0.25
"""How long an answer is kept (seconds of monotonic time); :func:`readiness_of` uses it for new
clients. 0 asks rclpy on every call."""

FRESH_S = 1e-3
"""An answer younger than this counts as fresh for :meth:`Readiness.ready_now`, so a behaviour that
has just asked (a stale cache refreshed by :meth:`Readiness.ready`) does not ask twice in a tick."""


class Readiness:
    """The latest answer of ``ask()`` (is the server up?), kept for ``period`` seconds of ``monotonic``."""

    def __init__(
        self,
        ask: Callable[[], bool],
        period: float | None = None,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self._ask = ask
        self.period = READINESS_PERIOD_S if period is None else float(period)
        if self.period < 0:
            raise ValueError(f"readiness period must be >= 0 s, got {self.period}")
        self._monotonic = monotonic
        self._answer = False
        self._asked_at = -float("inf")
        self.asked = 0  # how many times rclpy was asked (for tests and benchmarks)

    def _refresh(self, now: float) -> bool:
        self._answer = bool(self._ask())
        self._asked_at = now
        self.asked += 1
        return self._answer

    def ready(self) -> bool:
        """Whether the server is up, by an answer at most ``period`` seconds old: for waiting."""
        now = self._monotonic()
        if now - self._asked_at >= self.period:
            return self._refresh(now)
        return self._answer

    def ready_now(self) -> bool:
        """Whether the server is up, by an answer at most ``FRESH_S`` old: for acting on it."""
        now = self._monotonic()
        if now - self._asked_at >= FRESH_S:
            return self._refresh(now)
        return self._answer

    def wait(self, waited: float, timeout: float) -> bool | None:
        """A behaviour's wait for the server, ``waited`` seconds into it: True when a fresh answer
        says it is up (send now), False when a fresh answer says it is not after ``timeout`` (fail
        now), None while it is still worth waiting (cached answers, so a tick asks rclpy at most
        once a ``period``)."""
        up = self.ready()
        if up or waited > timeout:
            up = self.ready_now()
        if up:
            return True
        return False if waited > timeout else None


def readiness_of(client: Any) -> Readiness:
    """The one :class:`Readiness` of an rclpy action client (``server_is_ready``) or service client
    (``service_is_ready``), kept on the client so every behaviour sharing the client shares it."""
    readiness = getattr(client, "_tlt_readiness", None)
    if readiness is None:
        ask = getattr(client, "server_is_ready", None) or client.service_is_ready
        readiness = Readiness(ask)
        client._tlt_readiness = readiness
    return readiness


__all__ = ["FRESH_S", "READINESS_PERIOD_S", "Readiness", "readiness_of"]
