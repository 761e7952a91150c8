"""The thread under the process watches (:mod:`tlt_common.ros.sim_clock_watch`,
:mod:`tlt_common.ros.topic_silence_watch`): on the wall clock and outside the executor, so it still runs
when the executor, or the sim time that drives it, does not."""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from typing import Self


class WatchThread(ABC):
    """A daemon thread running :meth:`_run`; :meth:`_next_period` waits ``period_s`` and is False
    once :meth:`stop` was called."""

    def __init__(self, name: str, what: str, period_s: float) -> None:
        self.name = name
        self.period_s = period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"{name}-{what}-watch", daemon=True)

    def start(self) -> Self:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2 * self.period_s + 1.0)

    def _next_period(self) -> bool:
        return not self._stop.wait(self.period_s)

    @abstractmethod
    def _run(self) -> None:
        """The watch itself: loop on :meth:`_next_period` and return when it is False."""


__all__ = ["WatchThread"]
