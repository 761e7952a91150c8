"""A token bucket: at most ``burst`` at once and ``rate`` a second after, for reports that a flood
of bad input must not turn into a flood of log lines or downlink events."""

from __future__ import annotations

import time
from collections.abc import Callable


class TokenBucket:
    """:meth:`allow` says whether one more report may go now; :attr:`suppressed` counts those
    refused since the caller last took it (:meth:`take_suppressed`)."""

    def __init__(self, rate: float, burst: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.rate, self.burst, self.clock = float(rate), float(burst), clock
        self.tokens = self.burst
        self.stamp: float | None = None
        self.suppressed = 0

    def allow(self) -> bool:
        now = self.clock()
        if self.stamp is not None:
            self.tokens = min(self.burst, self.tokens + (now - self.stamp) * self.rate)
        self.stamp = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        self.suppressed += 1
        return False

    def take_suppressed(self) -> int:
        """The reports refused since the last call."""
        count, self.suppressed = self.suppressed, 0
        return count


__all__ = ["TokenBucket"]
