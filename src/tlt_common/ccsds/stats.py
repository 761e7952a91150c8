"""Counters of one end of the ground link: packets, bytes, gaps, CRC errors and rejections."""

from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass, field

from tlt_common.ccsds.codec import ParseResult, Rejection
from tlt_common.ccsds.reasons import Reason
from tlt_common.ccsds.sequence import GapTracker

# Rejections that say a packet is not the other end's word: forged, altered, replayed or under a
# key that is unknown or retired.
AUTH_REASONS = frozenset({Reason.BAD_AUTH, Reason.UNKNOWN_KEY, Reason.REPLAY})
# Distinct foreign sources counted by name; any further ones are counted together as "other", so a
# flood from many addresses cannot grow the counters without bound.
MAX_TRACKED_SOURCES = 64


@dataclass
class LinkStats:
    """Totals since start. ``record_rx``/``record_tx`` are safe to call from several threads."""

    packets_rx: int = 0
    bytes_rx: int = 0
    packets_tx: int = 0
    bytes_tx: int = 0
    crc_errors: int = 0
    rejections: int = 0
    auth_rejections: int = 0
    commands_accepted: int = 0
    source_rejections: int = 0
    by_reason: Counter = field(default_factory=Counter)
    by_source: Counter = field(default_factory=Counter)
    sequence: GapTracker = field(default_factory=GapTracker)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def record_rx(self, size: int, result: ParseResult) -> int:
        """Count one received datagram; return the packets found missing before it (gap)."""
        with self._lock:
            self.packets_rx += 1
            self.bytes_rx += size
            if isinstance(result, Rejection):
                self.rejections += 1
                self.by_reason[result.reason.label] += 1
                if result.reason is Reason.BAD_CRC:
                    self.crc_errors += 1
                elif result.reason in AUTH_REASONS:
                    self.auth_rejections += 1
                return 0
            return self.sequence.observe(result.apid, result.seq_count).missing

    def record_foreign(self, size: int, source: tuple[str, int]) -> None:
        """Count one datagram dropped unparsed because ``source`` is not an accepted peer."""
        with self._lock:
            self.packets_rx += 1
            self.bytes_rx += size
            self.rejections += 1
            self.source_rejections += 1
            self.by_reason[Reason.SOURCE.label] += 1
            name = f"{source[0]}:{source[1]}"
            if name not in self.by_source and len(self.by_source) >= MAX_TRACKED_SOURCES:
                name = "other"
            self.by_source[name] += 1

    def record_accepted(self) -> None:
        with self._lock:
            self.commands_accepted += 1

    def record_refusal(self, reason: Reason) -> None:
        """Count a command that parsed and authenticated but was refused by its receiver."""
        with self._lock:
            self.rejections += 1
            self.by_reason[reason.label] += 1

    def record_tx(self, size: int) -> None:
        with self._lock:
            self.packets_tx += 1
            self.bytes_tx += size

    @property
    def gaps(self) -> int:
        return self.sequence.gaps

    @property
    def missing(self) -> int:
        return self.sequence.missing

    def as_fields(self) -> dict[str, int]:
        """The values of the ``link_stats`` telemetry packet (counters clipped to their widths)."""
        with self._lock:
            u32 = 2**32 - 1
            return {
                "packets_rx": min(self.packets_rx, u32),
                "bytes_rx": self.bytes_rx,
                "packets_tx": min(self.packets_tx, u32),
                "bytes_tx": self.bytes_tx,
                "gaps": min(self.sequence.gaps, u32),
                "missing": min(self.sequence.missing, u32),
                "crc_errors": min(self.crc_errors, u32),
                "rejections": min(self.rejections, u32),
                "commands_accepted": min(self.commands_accepted, u32),
                "source_rejections": min(self.source_rejections, u32),
            }


__all__ = ["AUTH_REASONS", "MAX_TRACKED_SOURCES", "LinkStats"]
