"""Ground link authentication in the spirit of CCSDS SDLS (355.0-B): keys, MACs and anti-replay.

Every command carries a security header (key id, 64-bit sequence number) and an HMAC-SHA256
trailer over everything before it. The CRS verifies the trailer in constant time and accepts a
sequence number only if it is above the last one accepted for that key; that last number is
persisted atomically so a restarted CRS still refuses old commands.

Telemetry is authenticated the same way in the other direction with keys of its own
(:mod:`tlt_common.ccsds.tm_security`); this module holds the MAC primitives both directions use.

Key files live outside the repository (path from configuration or ``$TLT_GROUND_KEY_FILE``). Each
non-comment line is ``<key id> <hex key>`` (a command key) or ``tm <key id> <hex key>`` (a
telemetry key), with keys of at least 16 bytes; the file must not be readable by group or others.
One file holds both kinds so both ends read one secret, but a command key never signs telemetry.
"""

from __future__ import annotations

import hmac
import json
import os
import stat
import threading
import time
from pathlib import Path
from typing import Protocol

KEY_FILE_ENV = "TLT_GROUND_KEY_FILE"
MIN_KEY_BYTES = 16
MAX_SECURITY_SEQ = 2**64 - 1


class KeyLookup(Protocol):
    """Keys by key id (:class:`KeyRing`, or the GSW's telemetry verifier)."""

    def get(self, key_id: int) -> bytes | None: ...


class ReplayCheck(Protocol):
    """Accepts a security sequence number once per key id (:class:`ReplayGuard`)."""

    def accept(self, key_id: int, seq: int) -> bool: ...

    def last(self, key_id: int) -> int | None: ...


class KeyFileError(ValueError):
    """The key file is missing, unreadable, too open or malformed."""


class ReplayStateError(RuntimeError):
    """The persisted anti-replay state cannot be read or written."""


def compute_mac(key: bytes, data: bytes, size: int = 32) -> bytes:
    """HMAC-SHA256 of ``data`` truncated to ``size`` bytes."""
    return hmac.digest(key, data, "sha256")[:size]  # the one-shot C path: no HMAC object per packet


def verify_mac(key: bytes, data: bytes, mac: bytes) -> bool:
    """True if ``mac`` is the MAC of ``data``; the comparison takes constant time."""
    return hmac.compare_digest(compute_mac(key, data, len(mac)), mac)


class KeyRing:
    """Shared command keys by key id, and the telemetry keys (:attr:`telemetry`, a ring of its own).

    ``get`` returns None for an unknown id.
    """

    def __init__(self, keys: dict[int, bytes], tm_keys: dict[int, bytes] | None = None) -> None:
        for key_id, key in (*keys.items(), *(tm_keys or {}).items()):
            if not 0 <= key_id <= 0xFFFF:
                raise KeyFileError(f"key id {key_id} does not fit 16 bits")
            if len(key) < MIN_KEY_BYTES:
                raise KeyFileError(f"key {key_id} is {len(key)} bytes, at least {MIN_KEY_BYTES} are needed")
        self._keys = dict(keys)
        self._telemetry = KeyRing(tm_keys) if tm_keys else None
        self.path: Path | None = None  # the key file it was loaded from, if any (see :meth:`reload`)

    @property
    def telemetry(self) -> KeyRing:
        """The telemetry keys (an empty ring if the key file has none)."""
        return self._telemetry if self._telemetry is not None else KeyRing({})

    def get(self, key_id: int) -> bytes | None:
        return self._keys.get(key_id)

    @property
    def key_ids(self) -> list[int]:
        return sorted(self._keys)

    @classmethod
    def load(cls, path: str | Path | None = None) -> KeyRing:
        """Read a key file (``path`` or ``$TLT_GROUND_KEY_FILE``); raise :class:`KeyFileError`."""
        chosen = path or os.environ.get(KEY_FILE_ENV)
        if not chosen:
            raise KeyFileError(f"no key file given (pass a path or set ${KEY_FILE_ENV})")
        file = Path(chosen)
        try:
            mode = file.stat().st_mode
            text = file.read_text(encoding="ascii")
        except (OSError, UnicodeDecodeError) as exc:
            raise KeyFileError(f"{file}: cannot read key file: {exc}") from exc
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise KeyFileError(f"{file}: key file is accessible by group or others; run chmod 600 {file}")
        keys: dict[int, bytes] = {}
        tm_keys: dict[int, bytes] = {}
        for number, line in enumerate(text.splitlines(), start=1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            parts = line.split()
            target = keys
            if parts[0] == "tm":
                target, parts = tm_keys, parts[1:]
            try:
                if len(parts) != 2:
                    raise ValueError("expected '<key id> <hex key>' or 'tm <key id> <hex key>'")
                key_id, key = int(parts[0], 0), bytes.fromhex(parts[1])
            except ValueError as exc:
                raise KeyFileError(f"{file}: line {number}: {exc}") from None
            if key_id in target:
                raise KeyFileError(f"{file}: line {number}: key id {key_id} appears twice")
            target[key_id] = key
        if not keys:
            raise KeyFileError(f"{file}: no keys in key file")
        try:
            ring = cls(keys, tm_keys)
            ring.path = file
            return ring
        except KeyFileError as exc:
            raise KeyFileError(f"{file}: {exc}") from None

    def reload(self) -> KeyRing:
        """The key file read again (keys added for a rotation); this ring if it came from no file.
        Raises :class:`KeyFileError` like :meth:`load`."""
        return KeyRing.load(self.path) if self.path is not None else self


def write_key_file(path: str | Path, keys: dict[int, bytes], tm_keys: dict[int, bytes] | None = None) -> Path:
    """Create a key file readable by its owner only (for set-up tools and tests): command keys
    ``keys`` and telemetry keys ``tm_keys``."""
    file = Path(path)
    file.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    fd = os.open(file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="ascii") as out:
        out.write("# TLT ground link keys: commands '<id> <hex key>', telemetry 'tm <id> <hex key>'\n")
        for key_id, key in sorted(keys.items()):
            out.write(f"{key_id} {key.hex()}\n")
        for key_id, key in sorted((tm_keys or {}).items()):
            out.write(f"tm {key_id} {key.hex()}\n")
    os.chmod(file, 0o600)
    return file


def _atomic_write_json(path: Path, data: object) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.write(fd, json.dumps(data, sort_keys=True).encode("ascii"))
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    # The rename is durable only once the directory entry is on disk.
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


class ReplayGuard:
    """Last accepted security sequence number per key id, persisted in a JSON file.

    ``is_fresh`` tells whether a number is above the last accepted one; ``accept`` records it and
    returns only after the new state is on disk (temporary file, fsync, rename), so a command is
    never acted on before its number is durable. A missing file means nothing was accepted yet; an
    unreadable or corrupt one raises :class:`ReplayStateError` rather than silently starting over.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        self._last: dict[int, int] = {}
        if self.path.exists():
            try:
                raw = json.loads(self.path.read_text(encoding="ascii"))
                self._last = {int(k): int(v) for k, v in raw["last_accepted"].items()}
            except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
                raise ReplayStateError(
                    f"{self.path}: anti-replay state unreadable ({exc}); refusing to start, since a "
                    "reset would admit old commands. Inspect the file, and delete it only if every "
                    "previously sent command must be accepted again."
                ) from exc
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)

    def last(self, key_id: int) -> int | None:
        return self._last.get(key_id)

    def is_fresh(self, key_id: int, seq: int) -> bool:
        last = self._last.get(key_id)
        return last is None or seq > last

    def accept(self, key_id: int, seq: int) -> bool:
        """Record ``seq`` as accepted if it is fresh; False (nothing written) if it is a replay."""
        with self._lock:
            if not self.is_fresh(key_id, seq):
                return False
            state = dict(self._last)
            state[key_id] = seq
            try:
                _atomic_write_json(
                    self.path,
                    {"last_accepted": {str(k): v for k, v in state.items()}, "updated": time.time()},
                )
            except OSError as exc:
                raise ReplayStateError(f"{self.path}: cannot persist anti-replay state: {exc}") from exc
            self._last = state
            return True


class CommandSequencer:
    """Issues the GSW's security sequence numbers: strictly increasing, also across restarts.

    The number is the larger of (last issued + 1) and the wall clock in microseconds, so a GSW
    that lost its state file still issues numbers above anything it sent before (as long as the
    clock does not go back); with ``state_path`` the last number is also persisted.
    """

    def __init__(self, state_path: str | Path | None = None) -> None:
        self.state_path = Path(state_path) if state_path else None
        self._last = 0
        self._lock = threading.Lock()
        if self.state_path is not None and self.state_path.exists():
            try:
                self._last = int(json.loads(self.state_path.read_text(encoding="ascii"))["last_issued"])
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise ReplayStateError(
                    f"{self.state_path}: command sequence state unreadable: {exc}"
                ) from exc

    def next(self) -> int:
        with self._lock:
            seq = max(self._last + 1, time.time_ns() // 1000)
            if seq > MAX_SECURITY_SEQ:
                raise ReplayStateError("security sequence numbers exhausted; rotate the key")
            if self.state_path is not None:
                self.state_path.parent.mkdir(parents=True, exist_ok=True)
                _atomic_write_json(self.state_path, {"last_issued": seq})
            self._last = seq
            return seq


__all__ = [
    "KEY_FILE_ENV",
    "CommandSequencer",
    "KeyFileError",
    "KeyRing",
    "ReplayGuard",
    "ReplayStateError",
    "compute_mac",
    "verify_mac",
    "write_key_file",
]
