"""Which peer addresses one end of the ground link accepts datagrams from (``accept_from``).

An entry is an IPv4 address (any port) or ``address:port``. A receiver checks the source of every
datagram before it parses a byte of it: a datagram from any other address is dropped, counted per
source in :class:`~tlt_common.ccsds.stats.LinkStats` and logged at a bounded rate. Authentication
still applies to what is accepted; the check keeps strangers from costing a MAC each and says who
is talking to a link that should hear only its peer.
"""

from __future__ import annotations

import ipaddress
import logging
import time
from collections.abc import Callable, Iterable

from tlt_common.rate_limit import TokenBucket

Source = tuple[str, int | None]
# Drops from foreign sources are logged at most this often per second (each is counted regardless).
DROP_LOGS_PER_S = 5


def parse_source(text: str) -> Source:
    """``"10.0.0.1"`` (any port) or ``"10.0.0.1:52001"``; raise ValueError saying what is wrong."""
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"expected an IPv4 address or address:port, got {text!r}")
    host, sep, port = text.strip().partition(":")
    try:
        address = str(ipaddress.IPv4Address(host))
    except ValueError:
        raise ValueError(f"{host!r} is not an IPv4 address") from None
    if not sep:
        return address, None
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"{port!r} is not a UDP port (1 ... 65535)")
    return address, int(port)


def parse_sources(entries: Iterable[str] | None) -> list[Source] | None:
    """The ``accept_from`` entries of a loaded configuration (None: every source accepted)."""
    return None if entries is None else [parse_source(e) for e in entries]


def check_sources(entries: list) -> str | None:
    """Schema check of an ``accept_from`` list: the problem with its first bad entry, or None."""
    for i, entry in enumerate(entries):
        try:
            parse_source(entry)
        except ValueError as exc:
            return f"item {i}: {exc}"
    return None


def describe(source: tuple[str, int]) -> str:
    return f"{source[0]}:{source[1]}"


class SourceFilter:
    """The accepted sources of one receiver; ``None`` accepts every source.

    :meth:`allows` is the check; :meth:`note_drop` logs a dropped datagram, at most
    ``DROP_LOGS_PER_S`` lines a second.
    """

    def __init__(
        self,
        accepted: Iterable[Source] | None,
        logger: logging.Logger,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.accepted = None if accepted is None else frozenset(accepted)
        self._log = logger
        self._logs = TokenBucket(DROP_LOGS_PER_S, DROP_LOGS_PER_S, clock)

    def allows(self, source: tuple[str, int]) -> bool:
        if self.accepted is None:
            return True
        host, port = source[0], source[1]
        return (host, None) in self.accepted or (host, port) in self.accepted

    def note_drop(self, source: tuple[str, int]) -> str:
        """Log one dropped datagram (rate limited); return the sentence that says why."""
        text = f"datagram from {describe(source)} dropped: not a configured source"
        if self._logs.allow():
            self._log.warning("%s", text)
        return text


__all__ = [
    "DROP_LOGS_PER_S",
    "Source",
    "SourceFilter",
    "check_sources",
    "describe",
    "parse_source",
    "parse_sources",
]
