"""14-bit CCSDS packet sequence counts: issuing them per APID and checking received ones for gaps.

The count wraps from 16383 to 0. On receive, the distance from the last count seen on an APID
(modulo 2^14) says what happened: 1 is in order, 2..8192 means that many minus one packets were
lost (a gap), 0 is a duplicate, and anything larger is a late (reordered) packet, which is counted
but does not move the expected count backwards.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

SEQ_MODULO = 1 << 14
_HALF = SEQ_MODULO // 2


class SequenceCounters:
    """Per-APID send counters: ``next(apid)`` returns 0, 1, ..., 16383, 0, ..."""

    def __init__(self) -> None:
        self._next: dict[int, int] = {}
        self._lock = threading.Lock()

    def next(self, apid: int) -> int:
        with self._lock:
            count = self._next.get(apid, 0)
            self._next[apid] = (count + 1) % SEQ_MODULO
            return count


@dataclass
class GapReport:
    """What one received count meant: ``missing`` packets lost before it, or a duplicate/late one."""

    missing: int = 0
    duplicate: bool = False
    late: bool = False


class GapTracker:
    """Checks received sequence counts per APID and totals gaps, missing packets and reorders."""

    def __init__(self) -> None:
        self._last: dict[int, int] = {}
        self.gaps = 0
        self.missing = 0
        self.duplicates = 0
        self.late = 0

    def observe(self, apid: int, seq_count: int) -> GapReport:
        last = self._last.get(apid)
        if last is None:
            self._last[apid] = seq_count
            return GapReport()
        delta = (seq_count - last) % SEQ_MODULO
        if delta == 0:
            self.duplicates += 1
            return GapReport(duplicate=True)
        if delta > _HALF:
            self.late += 1
            return GapReport(late=True)
        self._last[apid] = seq_count
        if delta == 1:
            return GapReport()
        self.gaps += 1
        self.missing += delta - 1
        return GapReport(missing=delta - 1)

    def reset(self, apid: int | None = None) -> None:
        """Forget the last count (all APIDs, or one), e.g. when the other end restarted."""
        if apid is None:
            self._last.clear()
        else:
            self._last.pop(apid, None)


__all__ = ["SEQ_MODULO", "GapReport", "GapTracker", "SequenceCounters"]
