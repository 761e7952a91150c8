"""The telemetry archive's SQLite schema and its migrations.

``schema_version`` holds one row per applied migration. :func:`migrate` applies, in one
transaction each, every migration above the stored version, and refuses a database written by a
newer GSW (its version is above the last migration known here) rather than guessing.

Tables (version 1):

* ``packets``: every raw packet sent (``tx``) or received (``rx``), accepted or not: GSW time,
  packet time, APID, sequence count, type, kind, status (``ok`` or the rejection reason), raw bytes.
* ``field_names``: (kind, field name) -> small integer id, so each stored value is compact.
* ``fields``: every decoded field of every accepted packet: field id, packet id, packet time, value;
  one b-tree clustered by (field id, packet id), so a field's history (plots, export) is one range
  read in arrival order, a packet's fields are point reads by its kind's field ids, and an insert
  touches no secondary index (this is what lets the recorder ingest tens of thousands of packets/s).
* view ``field_values``: ``fields`` joined with their names (packet_id, kind, name, time, value).
"""

from __future__ import annotations

import sqlite3
import time

MIGRATIONS: tuple[tuple[int, str], ...] = (
    (
        1,
        """
        CREATE TABLE packets (
            id INTEGER PRIMARY KEY,
            direction TEXT NOT NULL CHECK (direction IN ('rx', 'tx')),
            recorded_at REAL NOT NULL,
            packet_time REAL,
            apid INTEGER,
            seq_count INTEGER,
            packet_type TEXT,
            kind TEXT,
            status TEXT NOT NULL,
            detail TEXT,
            raw BLOB NOT NULL
        );
        CREATE INDEX packets_by_time ON packets (recorded_at);
        CREATE INDEX packets_by_kind ON packets (kind, recorded_at);
        CREATE TABLE field_names (
            id INTEGER PRIMARY KEY,
            kind TEXT NOT NULL,
            name TEXT NOT NULL,
            UNIQUE (kind, name)
        );
        CREATE TABLE fields (
            field_id INTEGER NOT NULL REFERENCES field_names (id),
            packet_id INTEGER NOT NULL REFERENCES packets (id),
            time REAL NOT NULL,
            value,
            PRIMARY KEY (field_id, packet_id)
        ) WITHOUT ROWID;
        CREATE VIEW field_values AS
            SELECT f.packet_id AS packet_id, n.kind AS kind, n.name AS name, f.time AS time, f.value AS value
            FROM fields AS f JOIN field_names AS n ON n.id = f.field_id;
        """,
    ),
)
LATEST_VERSION = MIGRATIONS[-1][0]


class SchemaError(RuntimeError):
    """The archive's schema is newer than this software or a migration failed."""


def current_version(conn: sqlite3.Connection) -> int:
    """The highest applied migration, 0 for an empty database."""
    exists = conn.execute(
        "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'schema_version'"
    ).fetchone()
    if not exists:
        return 0
    row = conn.execute("SELECT MAX(version) FROM schema_version").fetchone()
    return int(row[0] or 0)


def migrate(conn: sqlite3.Connection) -> int:
    """Bring the database to :data:`LATEST_VERSION`; return the version it is at."""
    conn.execute(
        "CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL, applied_at REAL NOT NULL)"
    )
    version = current_version(conn)
    if version > LATEST_VERSION:
        raise SchemaError(
            f"archive schema version {version} is newer than this GSW understands ({LATEST_VERSION}); "
            "use a newer GSW or another archive file"
        )
    for number, script in MIGRATIONS:
        if number <= version:
            continue
        try:
            conn.execute("BEGIN IMMEDIATE")
            for statement in _statements(script):
                conn.execute(statement)
            conn.execute(
                "INSERT INTO schema_version (version, applied_at) VALUES (?, ?)", (number, time.time())
            )
            conn.execute("COMMIT")
        except sqlite3.Error:
            if conn.in_transaction:
                conn.execute("ROLLBACK")
            raise
        version = number
    return version


def _statements(script: str) -> list[str]:
    return [part.strip() for part in script.split(";") if part.strip()]


__all__ = ["LATEST_VERSION", "MIGRATIONS", "SchemaError", "current_version", "migrate"]
