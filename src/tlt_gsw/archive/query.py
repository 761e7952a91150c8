"""Read-only queries on the telemetry archive: packets, field series, and CSV export.

Every display of the GSW (CLI and GUI) is a query here on the database the recorder writes
(Fig. 6). Connections are opened read-only, so a query can never change or lock the archive for
the recorder beyond SQLite's normal WAL reader rules.
"""

from __future__ import annotations

import csv
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from tlt_gsw.archive.schema import LATEST_VERSION, current_version


class ArchiveError(RuntimeError):
    """The archive cannot be opened or queried."""


def open_archive(path: str | Path) -> sqlite3.Connection:
    """Open an archive read-only; raise :class:`ArchiveError` if it is missing or not an archive."""
    file = Path(path)
    if not file.exists():
        raise ArchiveError(f"archive {file} does not exist")
    try:
        conn = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro", uri=True, timeout=2.0)
        version = current_version(conn)
    except sqlite3.Error as exc:
        raise ArchiveError(f"archive {file}: {exc}") from exc
    if version == 0 or version > LATEST_VERSION:
        conn.close()
        raise ArchiveError(
            f"archive {file}: schema version {version} is not one this GSW reads (1..{LATEST_VERSION})"
        )
    return conn


@dataclass(frozen=True)
class PacketRow:
    id: int
    direction: str
    recorded_at: float
    packet_time: float | None
    apid: int | None
    seq_count: int | None
    packet_type: str | None
    kind: str | None
    status: str
    detail: str | None
    raw: bytes


def packets(
    conn: sqlite3.Connection,
    *,
    kind: str | None = None,
    status: str | None = None,
    direction: str | None = None,
    since: float | None = None,
    until: float | None = None,
    limit: int = 100,
    newest_first: bool = True,
) -> list[PacketRow]:
    """Packets matching every given filter, newest first by default."""
    where, args = _filters(kind=kind, status=status, direction=direction, since=since, until=until)
    order = "DESC" if newest_first else "ASC"
    rows = conn.execute(
        "SELECT id, direction, recorded_at, packet_time, apid, seq_count, packet_type, kind, status, detail, "
        f"raw FROM packets {where} ORDER BY id {order} LIMIT ?",
        (*args, int(limit)),
    ).fetchall()
    return [PacketRow(*row) for row in rows]


def _filters(**conditions: Any) -> tuple[str, list[Any]]:
    clauses, args = [], []
    for name, value in conditions.items():
        if value is None:
            continue
        if name == "since":
            clauses.append("recorded_at >= ?")
        elif name == "until":
            clauses.append("recorded_at <= ?")
        else:
            clauses.append(f"{name} = ?")
        args.append(value)
    return ("WHERE " + " AND ".join(clauses)) if clauses else "", args


def packet_fields(conn: sqlite3.Connection, packet_id: int) -> dict[str, Any]:
    """The decoded fields of one packet, in definition order (point reads by its kind's field ids)."""
    rows = conn.execute(
        "SELECT n.name, f.value FROM packets AS p JOIN field_names AS n ON n.kind = p.kind "
        "JOIN fields AS f ON f.field_id = n.id AND f.packet_id = p.id WHERE p.id = ? ORDER BY n.id",
        (packet_id,),
    ).fetchall()
    return dict(rows)


def field_series(
    conn: sqlite3.Connection,
    kind: str,
    name: str,
    *,
    since: float | None = None,
    until: float | None = None,
    limit: int | None = None,
) -> list[tuple[float, Any]]:
    """(packet time, value) of one field in arrival order (one range of the fields b-tree)."""
    row = conn.execute("SELECT id FROM field_names WHERE kind = ? AND name = ?", (kind, name)).fetchone()
    if row is None:
        return []
    sql = "SELECT time, value FROM fields WHERE field_id = ?"
    args: list[Any] = [row[0]]
    if since is not None:
        sql += " AND time >= ?"
        args.append(since)
    if until is not None:
        sql += " AND time <= ?"
        args.append(until)
    sql += " ORDER BY packet_id"
    if limit is not None:
        sql += " LIMIT ?"
        args.append(int(limit))
    return conn.execute(sql, args).fetchall()


def counts(conn: sqlite3.Connection) -> list[tuple[str, str, str, int]]:
    """(direction, kind, status, packets) totals of the whole archive."""
    return conn.execute(
        "SELECT direction, COALESCE(kind, '-'), status, COUNT(*) FROM packets "
        "GROUP BY direction, kind, status ORDER BY direction, kind, status"
    ).fetchall()


def export_csv(
    conn: sqlite3.Connection,
    out: IO[str],
    kind: str,
    *,
    fields: list[str] | None = None,
    since: float | None = None,
    until: float | None = None,
) -> int:
    """Write one row per packet of ``kind``: time, seq_count, then the chosen fields; return the rows.

    Raises :class:`ArchiveError` if a requested field was never recorded for ``kind``.
    """
    known = [
        name for (name,) in conn.execute("SELECT name FROM field_names WHERE kind = ? ORDER BY id", (kind,))
    ]
    chosen = fields or known
    missing = [f for f in chosen if f not in known]
    if missing:
        raise ArchiveError(
            f"no field {missing[0]!r} recorded for {kind!r} (recorded: {', '.join(known) or 'none'})"
        )
    where, args = _filters(kind=kind, status="ok", since=since, until=until)
    writer = csv.writer(out)
    writer.writerow(["time", "recorded_at", "seq_count", *chosen])
    rows = 0
    current: int | None = None
    values: dict[str, Any] = {}
    head: tuple[Any, ...] = ()
    cursor = conn.execute(
        f"SELECT p.id, p.packet_time, p.recorded_at, p.seq_count, n.name, f.value "
        f"FROM (SELECT * FROM packets {where}) AS p "
        f"JOIN field_names AS n ON n.kind = p.kind "
        f"JOIN fields AS f ON f.field_id = n.id AND f.packet_id = p.id "
        f"ORDER BY p.id",
        args,
    )
    for pid, ptime, recorded, seq, name, value in cursor:
        if pid != current:
            if current is not None:
                writer.writerow([*head, *(_csv(values.get(f)) for f in chosen)])
                rows += 1
            current, values, head = pid, {}, (f"{ptime:.3f}", f"{recorded:.6f}", seq)
        values[name] = value
    if current is not None:
        writer.writerow([*head, *(_csv(values.get(f)) for f in chosen)])
        rows += 1
    return rows


def _csv(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.hex()
    return "" if value is None else value


__all__ = [
    "ArchiveError",
    "PacketRow",
    "counts",
    "export_csv",
    "field_series",
    "open_archive",
    "packet_fields",
    "packets",
]
