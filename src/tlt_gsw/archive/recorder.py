"""The GSW recorder: every raw packet and every decoded field into SQLite (paper §V.A, Fig. 6).

Reads nothing from the link itself; the caller hands it each datagram sent or received together
with what the parser made of it (:meth:`Recorder.record`). Packets are buffered in memory and
written in batched transactions (:meth:`Recorder.flush`, also triggered by batch size and age).

Durability: the database runs in WAL mode; a packet counts as committed once the ``flush`` that
wrote it returned, and a committed packet survives the process being killed at any moment.

Failures: if the database is locked, full or corrupt (or cannot be opened), ``flush`` keeps every
packet in the memory buffer, sets :attr:`Recorder.last_error` to a message saying what is wrong
and what to do, and writes the buffer once the database accepts writes again. Only if the buffer
reaches ``max_buffer`` packets are the oldest dropped, and they are counted in ``dropped``.
"""

from __future__ import annotations

import logging
import sqlite3
import threading
import time
from collections import deque
from collections.abc import Callable
from itertools import islice
from pathlib import Path

from tlt_common.ccsds.codec import Packet, ParseResult, Rejection
from tlt_gsw.archive.schema import SchemaError, migrate

_log = logging.getLogger(__name__)
_INT64_MAX = 2**63 - 1


# A buffered packet: (direction, recorded_at, raw bytes, parse result or None). A plain tuple,
# because the recorder handles tens of thousands per second.
_Pending = tuple[str, float, bytes, "ParseResult | None"]


def describe_db_error(path: Path, exc: BaseException) -> str:
    """An operator-facing sentence for a SQLite failure."""
    text = str(exc)
    lowered = text.lower()
    if "locked" in lowered or "busy" in lowered:
        hint = "another program holds a write lock on it; close it"
    elif "full" in lowered:
        hint = "the disk or the archive size limit is full; free space or start a new archive file"
    elif "not a database" in lowered or "malformed" in lowered or "corrupt" in lowered:
        hint = "the file is corrupt; move it aside (keep it for analysis) so a new archive can be created"
    elif "unable to open" in lowered or "readonly" in lowered or "read-only" in lowered:
        hint = "the file or its folder cannot be written; check the path and permissions"
    else:
        hint = "see the SQLite message"
    return f"archive {path}: {text} ({hint}); packets are kept in memory until it can be written"


class Recorder:
    """Batched, crash-safe writer of packets and decoded fields into a SQLite archive."""

    def __init__(
        self,
        path: str | Path,
        *,
        batch_size: int = 1000,
        flush_interval_s: float = 0.25,
        busy_timeout_s: float = 1.0,
        max_buffer: int = 1_000_000,
        max_bytes: int | None = None,
        synchronous: str = "NORMAL",
        retry_interval_s: float = 1.0,
        clock: Callable[[], float] = time.time,
    ) -> None:
        if synchronous not in ("NORMAL", "FULL"):
            raise ValueError("synchronous must be NORMAL or FULL")
        self.path = Path(path)
        self.batch_size = batch_size
        self.flush_interval_s = flush_interval_s
        self.busy_timeout_s = busy_timeout_s
        self.max_buffer = max_buffer
        self.max_bytes = max_bytes
        self.synchronous = synchronous
        self.retry_interval_s = retry_interval_s
        self.clock = clock
        self.committed = 0
        self.dropped = 0
        self.last_error: str | None = None
        self._pending: deque[_Pending] = deque()
        self._lock = threading.RLock()
        self._conn: sqlite3.Connection | None = None
        self._field_ids: dict[tuple[str, str], int] = {}
        self._last_flush = time.monotonic()
        self._retry_at = 0.0
        self._open()

    # -- connection -------------------------------------------------------------------------
    def _open(self) -> bool:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            conn = sqlite3.connect(
                self.path, isolation_level=None, timeout=self.busy_timeout_s, check_same_thread=False
            )
        except (OSError, sqlite3.Error) as exc:
            self._fail(exc)
            return False
        try:
            mode = conn.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if str(mode).lower() != "wal":
                raise sqlite3.OperationalError(f"could not switch to WAL mode (journal mode is {mode})")
            conn.execute(f"PRAGMA synchronous={self.synchronous}")
            if self.max_bytes is not None:
                page = conn.execute("PRAGMA page_size").fetchone()[0]
                conn.execute(f"PRAGMA max_page_count={max(1, self.max_bytes // page)}")
            else:
                conn.execute("PRAGMA max_page_count=4294967294")
            migrate(conn)
            self._field_ids = {
                (k, n): i for i, k, n in conn.execute("SELECT id, kind, name FROM field_names")
            }
        except (sqlite3.Error, SchemaError) as exc:
            conn.close()
            self._fail(exc)
            return False
        self._conn = conn
        return True

    def _fail(self, exc: BaseException) -> None:
        message = describe_db_error(self.path, exc)
        if message != self.last_error:
            _log.error("%s", message)
        self.last_error = message
        self._retry_at = time.monotonic() + self.retry_interval_s

    def set_size_limit(self, max_bytes: int | None) -> None:
        """Change the archive size cap (None: only the disk limits it); applies from the next write."""
        with self._lock:
            self.max_bytes = max_bytes
            self._close_conn()
            self._retry_at = 0.0

    @property
    def healthy(self) -> bool:
        """True while the last attempt to write succeeded."""
        return self._conn is not None and self.last_error is None

    @property
    def pending(self) -> int:
        """Packets buffered in memory, not yet committed."""
        return len(self._pending)

    # -- recording --------------------------------------------------------------------------
    def record(
        self, direction: str, raw: bytes, result: ParseResult | None = None, recorded_at: float | None = None
    ) -> None:
        """Buffer one packet (``direction`` ``"rx"`` or ``"tx"``); flush if the batch is due."""
        if direction not in ("rx", "tx"):
            raise ValueError(f"direction must be 'rx' or 'tx', not {direction!r}")
        item = (direction, self.clock() if recorded_at is None else recorded_at, bytes(raw), result)
        with self._lock:
            if len(self._pending) >= self.max_buffer:
                self._pending.popleft()
                self.dropped += 1
            self._pending.append(item)
            if (
                len(self._pending) >= self.batch_size
                or time.monotonic() - self._last_flush >= self.flush_interval_s
            ):
                self.flush(force=False)

    def maybe_flush(self) -> int:
        """Flush if the oldest buffered packet is older than the flush interval."""
        if self._pending and time.monotonic() - self._last_flush >= self.flush_interval_s:
            return self.flush(force=False)
        return 0

    def flush(self, force: bool = True) -> int:
        """Write the buffered packets, in transactions of at most 10 batches; return how many committed.

        On a database error nothing is lost: the packets stay buffered, :attr:`last_error` says
        why, and the next flush (after ``retry_interval_s`` unless ``force``) tries again.
        """
        with self._lock:
            self._last_flush = time.monotonic()
            if not self._pending:
                return 0
            if not force and time.monotonic() < self._retry_at:
                return 0
            if self._conn is None and not self._open():
                return 0
            written = 0
            chunk = max(1, 10 * self.batch_size)
            while self._pending:
                batch = list(islice(self._pending, chunk))
                try:
                    self._write(batch)
                except sqlite3.Error as exc:
                    self._rollback()
                    if isinstance(exc, sqlite3.DatabaseError) and not isinstance(
                        exc, sqlite3.OperationalError
                    ):
                        self._close_conn()  # corrupt: reopen from scratch on the next attempt
                    self._fail(exc)
                    return written
                for _ in batch:
                    self._pending.popleft()
                self.committed += len(batch)
                written += len(batch)
            if self.last_error is not None:
                _log.warning("archive %s writable again; %d buffered packet(s) written", self.path, written)
            self.last_error = None
            return written

    def _write(self, batch: list[_Pending]) -> None:
        conn = self._conn
        assert conn is not None
        conn.execute("BEGIN IMMEDIATE")
        (next_id,) = conn.execute("SELECT COALESCE(MAX(id), 0) + 1 FROM packets").fetchone()
        packet_rows: list[tuple[object, ...]] = []
        field_rows = []
        field_ids = self._field_ids
        for direction, recorded_at, raw, result in batch:
            if isinstance(result, Packet):
                kind, ptime = result.kind, result.time
                packet_rows.append(
                    (
                        next_id,
                        direction,
                        recorded_at,
                        ptime,
                        result.apid,
                        result.seq_count,
                        result.packet_type,
                        kind,
                        "ok",
                        None,
                        raw,
                    )
                )
                for name, value in result.fields.items():
                    fid = field_ids.get((kind, name)) or self._field_id(conn, kind, name)
                    if type(value) is int and value > _INT64_MAX:
                        value = str(value)  # SQLite integers are signed 64-bit; keep the digits
                    field_rows.append((fid, next_id, ptime, value))
            elif isinstance(result, Rejection):
                packet_rows.append(
                    (
                        next_id,
                        direction,
                        recorded_at,
                        None,
                        result.apid,
                        result.seq_count,
                        result.packet_type,
                        None,
                        result.reason.label,
                        result.detail,
                        raw,
                    )
                )
            else:
                packet_rows.append(
                    (next_id, direction, recorded_at, None, None, None, None, None, "undecoded", None, raw)
                )
            next_id += 1
        conn.executemany("INSERT INTO packets VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", packet_rows)
        conn.executemany("INSERT INTO fields VALUES (?, ?, ?, ?)", field_rows)
        conn.execute("COMMIT")

    def _field_id(self, conn: sqlite3.Connection, kind: str, name: str) -> int:
        conn.execute("INSERT OR IGNORE INTO field_names (kind, name) VALUES (?, ?)", (kind, name))
        (fid,) = conn.execute(
            "SELECT id FROM field_names WHERE kind = ? AND name = ?", (kind, name)
        ).fetchone()
        # A rollback clears this cache (see _rollback), so an id from an undone transaction is never reused.
        self._field_ids[(kind, name)] = fid
        return fid

    def _rollback(self) -> None:
        self._field_ids = {}
        if self._conn is None:
            return
        try:
            if self._conn.in_transaction:
                self._conn.execute("ROLLBACK")
            self._field_ids = {
                (k, n): i for i, k, n in self._conn.execute("SELECT id, kind, name FROM field_names")
            }
        except sqlite3.Error:
            self._close_conn()

    def _close_conn(self) -> None:
        if self._conn is not None:
            try:
                self._conn.close()
            except sqlite3.Error:
                pass
            self._conn = None

    def close(self) -> None:
        """Flush what is buffered (once) and close the database."""
        with self._lock:
            if self._pending:
                self.flush(force=True)
            if self._pending:
                _log.error(
                    "archive %s closed with %d packet(s) unwritten: %s",
                    self.path,
                    len(self._pending),
                    self.last_error,
                )
            self._close_conn()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["Recorder", "describe_db_error"]
