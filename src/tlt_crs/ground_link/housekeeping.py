"""When each housekeeping packet is due, at the rates of the definitions file or overrides.

Reads the ``rate_hz`` of every telemetry packet in the definitions (``link_stats`` excepted: the
ground link sends it itself). ``due(now)`` returns the packet kinds whose period has elapsed and
schedules their next time; a caller that fell behind by more than a period gets each late packet
once, not a burst. The clock is injectable so timing is tested without sleeping.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping

from tlt_common.ccsds.definitions import Definitions


class HousekeepingSchedule:
    """Per-kind periods and next due times; ``rates`` overrides (Hz; 0 switches a packet off)."""

    def __init__(
        self,
        definitions: Definitions,
        rates: Mapping[str, float] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        chosen = {
            name: pdef.rate_hz
            for name, pdef in definitions.telemetry.items()
            if pdef.rate_hz and name != "link_stats"
        }
        for name, rate in (rates or {}).items():
            if name not in definitions.telemetry or name == "link_stats":
                raise KeyError(f"no housekeeping packet {name!r} (packets: {', '.join(sorted(chosen))})")
            if rate < 0:
                raise ValueError(f"rate of {name} must be >= 0 Hz, got {rate}")
            chosen[name] = rate
        self.clock = clock
        self.periods = {name: 1.0 / rate for name, rate in chosen.items() if rate > 0}
        start = clock()
        self._next = dict.fromkeys(self.periods, start)

    def due(self, now: float | None = None) -> list[str]:
        """Kinds to send now, in definition order."""
        now = self.clock() if now is None else now
        out = []
        for name, period in self.periods.items():
            if now >= self._next[name]:
                out.append(name)
                following = self._next[name] + period
                self._next[name] = following if following > now else now + period
        return out

    def next_due(self) -> float | None:
        """The earliest time anything is due (for a timer), or None when nothing is scheduled."""
        return min(self._next.values(), default=None)


__all__ = ["HousekeepingSchedule"]
