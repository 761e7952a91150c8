"""Telemetry authentication state of both ends: the CRS's signer and the GSW's verifier.

Every telemetry packet carries a security header (key id, 64-bit security sequence number) and a
truncated HMAC-SHA256 trailer (:func:`tlt_common.ccsds.auth.compute_mac`) under a telemetry key,
never a command key. The byte layout is in :mod:`tlt_common.ccsds.codec`; this module decides
which key signs, which numbers are issued and which are accepted.

Sequence numbers: the CRS numbers its telemetry from a base taken from the wall clock in
microseconds when it starts, plus one per packet, over all APIDs and keys. A restarted CRS
therefore continues above everything it sent before (as long as it sent fewer than one packet per
microsecond on average and the clock does not go back), without a state file written per packet.

The GSW accepts a number once per key id: above the last accepted one, or inside a sliding
window of :data:`REPLAY_WINDOW` below it that has not been seen (UDP may reorder). A jump of 2 to
:data:`RESYNC_JUMP` is a gap (packets lost); a larger jump is a CRS restart (counted, not a gap).

Key rotation: the CRS signs with one key id at a time and :meth:`TelemetrySigner.switch_to_next`
moves it to the next higher id of its ring. The GSW accepts every telemetry key of its ring; once
it accepted a packet under a higher id, older ids stay accepted for ``overlap_s`` seconds (packets
still in flight) and are refused as ``unknown_key`` after.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from tlt_common.ccsds.auth import KeyFileError, KeyRing
from tlt_common.ccsds.codec import encode_telemetry
from tlt_common.ccsds.definitions import Definitions

REPLAY_WINDOW = 1024
RESYNC_JUMP = 1 << 20
_WINDOW_MASK = (1 << REPLAY_WINDOW) - 1


class TelemetrySigner:
    """The CRS's current telemetry key and its security sequence numbers (thread-safe)."""

    def __init__(self, keyring: KeyRing, key_id: int, *, base: int | None = None) -> None:
        if not keyring.key_ids:
            raise KeyFileError(
                "no telemetry keys ('tm <key id> <hex key>' lines) in the key file; "
                "make a new one with `tlt gsw keygen`"
            )
        if keyring.get(key_id) is None:
            raise KeyFileError(f"telemetry key id {key_id} is not in the key file (it has {keyring.key_ids})")
        self.keyring = keyring
        self._key_id = key_id
        self._next = time.time_ns() // 1000 if base is None else base
        self._lock = threading.Lock()

    @property
    def key_id(self) -> int:
        return self._key_id

    def encode(
        self,
        defs: Definitions,
        kind: str,
        values: Mapping[str, Any],
        *,
        seq_count: int,
        timestamp: float | None = None,
    ) -> bytes:
        """A signed telemetry packet of ``kind`` (see :func:`encode_telemetry`). A packet whose
        values do not fit raises and uses no sequence number, so it leaves no gap behind."""
        with self._lock:
            key = self.keyring.get(self._key_id)
            assert key is not None
            raw = encode_telemetry(
                defs,
                kind,
                values,
                seq_count=seq_count,
                timestamp=timestamp,
                key_id=self._key_id,
                key=key,
                security_seq=self._next,
            )
            self._next += 1
            return raw

    def switch_to_next(self, keyring: KeyRing | None = None) -> int:
        """Sign with the next higher key id from now on; return it. ``keyring`` replaces the
        telemetry keys first (the key file read again, with a key added for this rotation).
        Raise KeyFileError if there is no higher id (nothing changes then)."""
        with self._lock:
            if keyring is not None and keyring.get(self._key_id) is not None:
                self.keyring = keyring
            later = [k for k in self.keyring.key_ids if k > self._key_id]
            if not later:
                raise KeyFileError(
                    f"no telemetry key id above {self._key_id} in the key file "
                    f"(it has {self.keyring.key_ids})"
                )
            self._key_id = later[0]
            return self._key_id


@dataclass
class _KeyState:
    last: int
    seen: int  # bit i set: number last - i was accepted


class TelemetryVerifier:
    """The GSW's telemetry keys, their retirement and the replay window with gap counts.

    Passed to :func:`tlt_common.ccsds.codec.parse_datagram` as both the key lookup (``get``) and
    the replay check (``accept``, ``last``).
    """

    def __init__(
        self, keyring: KeyRing, *, overlap_s: float = 30.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.keyring = keyring
        self.overlap_s = overlap_s
        self.clock = clock
        self.gaps = 0
        self.missing = 0
        self.late = 0
        self.resyncs = 0
        self._state: dict[int, _KeyState] = {}
        self._retire_at: dict[int, float] = {}
        self._newest: int | None = None
        self._lock = threading.Lock()

    @property
    def key_ids(self) -> list[int]:
        return self.keyring.key_ids

    def add_keys(self, keyring: KeyRing) -> None:
        """Take the telemetry keys of ``keyring`` (the key file read again before a rotation)."""
        self.keyring = keyring

    def retired(self, key_id: int) -> bool:
        """True once ``key_id`` was superseded more than ``overlap_s`` seconds ago."""
        at = self._retire_at.get(key_id)
        return at is not None and self.clock() >= at

    def get(self, key_id: int) -> bytes | None:
        """The key of ``key_id``, or None if it is unknown or retired."""
        if self._retire_at and self.retired(key_id):
            return None
        return self.keyring.get(key_id)

    def last(self, key_id: int) -> int | None:
        state = self._state.get(key_id)
        return state.last if state else None

    def seed(self, key_id: int, last: int) -> None:
        """Treat every number up to ``last`` under ``key_id`` as accepted already (what an archive
        kept across a GSW restart holds), so none of it is taken again."""
        with self._lock:
            state = self._state.get(key_id)
            if state is None or last > state.last:
                self._state[key_id] = _KeyState(last, _WINDOW_MASK)

    def accept(self, key_id: int, seq: int) -> bool:
        """Record ``seq`` under ``key_id`` if it was never accepted and is inside the window."""
        with self._lock:
            state = self._state.get(key_id)
            if state is None:
                self._state[key_id] = _KeyState(seq, 1)
                self._note_key(key_id)
                return True
            if seq > state.last:
                jump = seq - state.last
                state.seen = ((state.seen << jump) | 1) & _WINDOW_MASK if jump < REPLAY_WINDOW else 1
                state.last = seq
                if jump > RESYNC_JUMP:
                    self.resyncs += 1
                elif jump > 1:
                    self.gaps += 1
                    self.missing += jump - 1
                return True
            offset = state.last - seq
            if offset >= REPLAY_WINDOW or state.seen >> offset & 1:
                return False
            state.seen |= 1 << offset
            self.late += 1
            self.missing = max(0, self.missing - 1)
            return True

    def _note_key(self, key_id: int) -> None:
        """A first packet under ``key_id``: if it is the newest id, start retiring the older ones."""
        if self._newest is not None and key_id <= self._newest:
            return
        self._newest = key_id
        deadline = self.clock() + self.overlap_s
        for older in self.keyring.key_ids:
            if older < key_id:
                self._retire_at.setdefault(older, deadline)


__all__ = ["REPLAY_WINDOW", "RESYNC_JUMP", "TelemetrySigner", "TelemetryVerifier"]
