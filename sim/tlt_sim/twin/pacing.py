"""Keeps simulated time at a real-time factor of wall time.

:class:`Pacer` is told the sim time after every step and sleeps until the wall clock has caught
up with ``sim / rtf``. It never makes up for lost time in a burst: when the simulation falls
behind by more than ``max_lag_s`` of wall time (a loaded machine, a pause while the twin waited
for a driver), it starts counting afresh from where it stands. ``rtf = 0`` sleeps only
``min_sleep_s`` per step: the twin's device threads (ptys, UR sockets) share the interpreter with
the simulation loop, and a loop that never sleeps starves their answers past the drivers' serial
timeouts. The clock and sleep are injectable so the behaviour is tested without waiting.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class Pacer:
    """Sleep so that sim time advances ``rtf`` times as fast as ``clock``."""

    def __init__(
        self,
        rtf: float,
        *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        max_lag_s: float = 0.2,
        min_sleep_s: float = 0.0,
    ) -> None:
        if rtf < 0:
            raise ValueError(f"real-time factor must be >= 0, got {rtf}")
        self.rtf = rtf
        self.clock = clock
        self.sleep = sleep
        self.max_lag_s = max_lag_s
        self.min_sleep_s = min_sleep_s
        self._wall0: float | None = None
        self._sim0 = 0.0
        self.rebases = 0

    def rebase(self, sim_time: float) -> None:
        """Count from ``sim_time`` at the present wall time."""
        self._wall0, self._sim0 = self.clock(), sim_time

    def wait(self, sim_time: float) -> None:
        """Return once the wall clock has reached ``sim_time`` at the set factor."""
        if self.rtf <= 0 or self._wall0 is None:
            if self.rtf > 0:
                self.rebase(sim_time)
            if self.min_sleep_s > 0:
                self.sleep(self.min_sleep_s)
            return
        due = self._wall0 + (sim_time - self._sim0) / self.rtf
        now = self.clock()
        if due - now > self.min_sleep_s:
            self.sleep(due - now)
            return
        if self.min_sleep_s > 0:
            self.sleep(self.min_sleep_s)
        if now - due > self.max_lag_s:
            self.rebases += 1
            self.rebase(sim_time)


__all__ = ["Pacer"]
