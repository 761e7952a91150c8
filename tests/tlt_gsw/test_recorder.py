"""The SQLite recorder: schema, stored packets and fields, failures, and a kill mid-stream."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import pytest

from tlt_common.ccsds.codec import encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_gsw.archive import LATEST_VERSION, Recorder
from tlt_gsw.archive import query as q

DEFS = load_definitions()


def tower(seq: int, count: int = 3, payload: bytes = b"\x01\x02") -> bytes:
    return encode_telemetry(
        DEFS,
        "hk_tower",
        {"member_count": count, "member_states": payload},
        seq_count=seq,
        timestamp=1_795_000_000.0 + seq,
    )


def record(rec: Recorder, raw: bytes) -> None:
    rec.record("rx", raw, parse_datagram(raw, DEFS))


def test_schema_wal_and_versions(tmp_path):
    path = tmp_path / "a.sqlite"
    with Recorder(path):
        pass
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert conn.execute("SELECT MAX(version) FROM schema_version").fetchone()[0] == LATEST_VERSION
    conn.close()
    with Recorder(path) as again:  # reopening applies nothing twice
        assert again.healthy
    conn = sqlite3.connect(path)
    assert conn.execute("SELECT COUNT(*) FROM schema_version").fetchone()[0] == LATEST_VERSION
    conn.execute("INSERT INTO schema_version VALUES (99, 0)")
    conn.commit()
    conn.close()
    newer = Recorder(path)
    assert not newer.healthy and "newer than this GSW" in newer.last_error
    with pytest.raises(q.ArchiveError, match="schema version 99"):
        q.open_archive(path)


def test_packets_and_decoded_fields_are_stored(tmp_path):
    path = tmp_path / "a.sqlite"
    with Recorder(path, batch_size=10_000) as rec:
        for seq in range(5):
            record(rec, tower(seq, count=seq))
        bad = tower(5)[:-1] + b"\x00"
        record(rec, bad)
        rec.record("tx", b"\x18\x10raw command")
        assert rec.pending == 7 and rec.committed == 0
        assert rec.flush() == 7
    conn = q.open_archive(path)
    rows = q.packets(conn, limit=10, newest_first=False)
    assert [(r.direction, r.kind, r.status) for r in rows] == [("rx", "hk_tower", "ok")] * 5 + [
        ("rx", None, "bad_crc"),
        ("tx", None, "undecoded"),
    ]
    assert rows[5].raw == bad and rows[0].seq_count == 0 and rows[0].apid == DEFS.packet("hk_tower").apid
    assert q.packet_fields(conn, rows[3].id) == {"member_count": 3, "member_states": b"\x01\x02"}
    series = q.field_series(conn, "hk_tower", "member_count")
    assert [v for _, v in series] == [0, 1, 2, 3, 4]
    assert series[1][0] == pytest.approx(1_795_000_001.0)
    view = conn.execute(
        "SELECT kind, name, value FROM field_values WHERE packet_id = ?", (rows[0].id,)
    ).fetchall()
    assert sorted(view) == [("hk_tower", "member_count", 0), ("hk_tower", "member_states", b"\x01\x02")]
    conn.close()


def test_batches_flush_by_size(tmp_path):
    with Recorder(tmp_path / "a.sqlite", batch_size=4, flush_interval_s=3600) as rec:
        for seq in range(10):
            record(rec, tower(seq))
        assert (rec.committed, rec.pending) == (8, 2)


def test_locked_database_keeps_packets_in_memory_until_free(tmp_path):
    path = tmp_path / "a.sqlite"
    rec = Recorder(path, busy_timeout_s=0.05, batch_size=10_000)
    blocker = sqlite3.connect(path, isolation_level=None)
    blocker.execute("BEGIN EXCLUSIVE")
    for seq in range(20):
        record(rec, tower(seq))
    assert rec.flush() == 0
    assert "locked" in rec.last_error and "kept in memory" in rec.last_error and not rec.healthy
    assert rec.pending == 20
    record(rec, tower(20))
    blocker.execute("ROLLBACK")
    blocker.close()
    assert rec.flush() == 21 and rec.healthy and rec.last_error is None
    rec.close()
    conn = q.open_archive(path)
    assert [r.seq_count for r in q.packets(conn, limit=100, newest_first=False)] == list(range(21))


def test_full_database_reports_and_recovers(tmp_path):
    path = tmp_path / "a.sqlite"
    rec = Recorder(path, batch_size=10_000, max_bytes=96 * 1024)
    big = bytes(1000)
    sent = 0
    while rec.last_error is None and sent < 2000:
        for _ in range(20):
            record(rec, tower(sent % 16384, payload=big))
            sent += 1
        rec.flush()
    assert "full" in rec.last_error
    assert rec.committed + rec.pending == sent and rec.pending > 0
    rec.set_size_limit(None)
    assert rec.flush() > 0 and rec.pending == 0
    rec.close()
    conn = q.open_archive(path)
    assert conn.execute("SELECT COUNT(*) FROM packets").fetchone()[0] == sent


def test_corrupt_file_is_reported_and_packets_kept(tmp_path):
    path = tmp_path / "a.sqlite"
    path.write_bytes(b"definitely not a database " * 400)
    rec = Recorder(path, retry_interval_s=0)
    assert not rec.healthy and "corrupt" in rec.last_error
    for seq in range(3):
        record(rec, tower(seq))
    assert rec.flush() == 0 and rec.pending == 3
    path.rename(tmp_path / "a.sqlite.corrupt")  # what the error tells the operator to do
    assert rec.flush() == 3 and rec.healthy
    rec.close()


WRITER = textwrap.dedent(
    """
    import sys
    from tlt_common.ccsds.codec import encode_telemetry, parse_datagram
    from tlt_common.ccsds.definitions import load_definitions
    from tlt_gsw.archive import Recorder

    defs = load_definitions()
    rec = Recorder(sys.argv[1], batch_size=50, flush_interval_s=3600)
    n = 0
    while True:
        raw = encode_telemetry(defs, "hk_tower", {"member_count": n % 65536, "member_states": b"x" * 40},
                               seq_count=n % 16384)
        rec.record("rx", raw, parse_datagram(raw, defs))
        n += 1
        if rec.pending == 0:
            print(rec.committed, flush=True)
    """
)


def test_kill_mid_stream_loses_no_committed_packet(tmp_path):
    path = tmp_path / "a.sqlite"
    child = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        reported = 0
        for _ in range(40):
            line = child.stdout.readline()
            assert line, "writer exited early"
            reported = int(line)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait(10)
        child.stdout.close()
    assert reported >= 40 * 50
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    stored = conn.execute("SELECT COUNT(*) FROM packets").fetchone()[0]
    assert stored >= reported
    counts = [
        v
        for (v,) in conn.execute(
            "SELECT value FROM field_values WHERE name = 'member_count' ORDER BY packet_id LIMIT ?",
            (reported,),
        )
    ]
    assert counts == list(range(reported))
    per_packet = conn.execute("SELECT COUNT(*) FROM fields").fetchone()[0]
    assert per_packet == 2 * stored  # never a packet without its fields, or fields without their packet
    conn.close()
    with Recorder(path) as reopened:  # and the archive goes on being written
        record(reopened, tower(0))
    assert sqlite3.connect(path).execute("SELECT COUNT(*) FROM packets").fetchone()[0] == stored + 1


def test_migrations_apply_in_order_and_a_failing_one_changes_nothing(tmp_path, monkeypatch):
    from tlt_gsw.archive import schema

    path = tmp_path / "a.sqlite"
    with Recorder(path) as rec:
        record(rec, tower(1))
    later = (
        *schema.MIGRATIONS,
        (
            2,
            "ALTER TABLE packets ADD COLUMN operator_note TEXT;"
            " CREATE INDEX notes ON packets (operator_note)",
        ),
    )
    monkeypatch.setattr(schema, "MIGRATIONS", later)
    monkeypatch.setattr(schema, "LATEST_VERSION", 2)
    conn = sqlite3.connect(path, isolation_level=None)
    assert schema.migrate(conn) == 2
    assert "operator_note" in [row[1] for row in conn.execute("PRAGMA table_info(packets)")]
    broken = (*later, (3, "CREATE TABLE kept_if_not_atomic (x); CREATE TABLE packets (x)"))
    monkeypatch.setattr(schema, "MIGRATIONS", broken)
    monkeypatch.setattr(schema, "LATEST_VERSION", 3)
    with pytest.raises(sqlite3.OperationalError, match="already exists"):
        schema.migrate(conn)
    assert schema.current_version(conn) == 2
    assert conn.execute("SELECT name FROM sqlite_master WHERE name = 'kept_if_not_atomic'").fetchone() is None
    assert conn.execute("SELECT COUNT(*) FROM packets").fetchone()[0] == 1
    conn.close()
