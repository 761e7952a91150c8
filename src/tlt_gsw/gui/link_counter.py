"""The link figures of the GSW end (packets, bytes, gaps, CRC errors, rejections, telemetry that
failed authentication, rates), counted packet by packet as the archive model applies the archived
packets."""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field

from tlt_common.ccsds.sequence import GapTracker
from tlt_common.ccsds.stats import AUTH_REASONS

_AUTH_STATUSES = frozenset(reason.label for reason in AUTH_REASONS)


@dataclass
class LinkFigures:
    """Counters of the GSW end, as the archive shows them up to the position."""

    packets_rx: int = 0
    bytes_rx: int = 0
    packets_tx: int = 0
    bytes_tx: int = 0
    crc_errors: int = 0
    rejections: int = 0
    # Received packets refused as forged, altered, replayed or under an unknown or retired key.
    auth_rejections: int = 0
    by_reason: Counter = field(default_factory=Counter)
    last_rx_at: float | None = None
    gaps: int = 0
    missing: int = 0
    rate_pps: float = 0.0
    rate_bps: float = 0.0


class LinkCounter:
    """Counts every archived packet into :class:`LinkFigures`; gaps per APID with the link's own
    :class:`GapTracker`, rates over ``rate_window_s`` with running sums."""

    def __init__(self, rate_window_s: float) -> None:
        self.rate_window_s = rate_window_s
        self.figures = LinkFigures()
        self._gaps = GapTracker()
        self._rate: deque[tuple[float, int]] = deque()
        self._rate_bytes = 0

    def figures_at(self, now: float | None) -> LinkFigures:
        """The counters, with rates over ``rate_window_s`` ending at ``now`` (none when ``None``)."""
        figures = self.figures
        figures.gaps, figures.missing = self._gaps.gaps, self._gaps.missing
        if now is None:
            figures.rate_pps = figures.rate_bps = 0.0
            return figures
        self._trim_rate(now)  # running sums over (now - window, newest]: no pass over the window
        figures.rate_pps = len(self._rate) / self.rate_window_s
        figures.rate_bps = self._rate_bytes / self.rate_window_s
        return figures

    def count(
        self, direction: str, status: str, apid: int | None, seq: int | None, size: int, recorded: float
    ) -> None:
        f = self.figures
        if direction == "rx":
            f.packets_rx += 1
            f.bytes_rx += size
            f.last_rx_at = recorded
            self._rate.append((recorded, size))
            self._rate_bytes += size
            self._trim_rate(recorded)
            if status != "ok":
                f.rejections += 1
                f.by_reason[status] += 1
                if status == "bad_crc":
                    f.crc_errors += 1
                elif status in _AUTH_STATUSES:
                    f.auth_rejections += 1
            elif apid is not None and seq is not None:
                self._gaps.observe(apid, seq)
        else:
            f.packets_tx += 1
            f.bytes_tx += size

    def _trim_rate(self, now: float) -> None:
        rate = self._rate
        while rate and rate[0][0] <= now - self.rate_window_s:
            self._rate_bytes -= rate.popleft()[1]


__all__ = ["LinkCounter", "LinkFigures"]
