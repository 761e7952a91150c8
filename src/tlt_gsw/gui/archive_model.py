"""What the GSW displays, computed by queries on the telemetry archive (paper Fig. 6).

The link thread writes every packet into the SQLite archive; :class:`ArchiveModel` reads it back
for the displays and never writes. It keeps a *position* (the id of the last packet applied) and
two ways to move it:

* :meth:`ArchiveModel.advance` reads only the packets after the position (``id > position``, a
  range of the packets rowid b-tree) and the decoded fields of those packets (ranges of the
  ``fields`` b-tree clustered by field id and packet id). Its cost follows the number of new
  packets, not the size of the archive; at most ``max_rows_per_refresh`` are read per call, so
  a backlog is caught up over several refreshes rather than in one long freeze.
* :meth:`ArchiveModel.seek` rebuilds the state as of any packet (replay: scrubbing, stepping
  back). It reads the newest packet of each kind at or before the position through the
  ``(kind, recorded_at)`` index, and counts the link figures with one scan of the packets up to the
  position (the only part whose cost grows with the archive).

State kept: the link figures (:mod:`~tlt_gsw.gui.link_counter`), the newest fields of every
housekeeping packet kind, the newest packets, events (the CRS's ``event`` packets, the datagrams
the GSW itself rejected and every limit crossing), the limit alarms with the operator's
acknowledgements (:mod:`~tlt_gsw.limit_events`: every packet of a limited kind is checked, not
only the newest one shown), commands sent with each acknowledgement stage matched by security
sequence number (a ``replay`` rejection of an already answered command answers a replayed copy:
counted on the command, not taken as its stage), each agent's tree status
(:mod:`~tlt_gsw.gui.agent_trees`, named with the ``tree_definition`` packets the agents sent:
:meth:`ArchiveModel.archived_shape`), and the series of plotted fields. The records it builds are in
:mod:`~tlt_gsw.gui.archive_records`.
"""

from __future__ import annotations

import sqlite3
import struct
from collections import deque
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from tlt_common.bt.shape_definition import DefinitionAssembler, DefinitionPart
from tlt_common.bt.status_codec import StatusCodecError, TreeShape
from tlt_common.ccsds.codec import PRIMARY_HEADER_LEN, TIME_LEN
from tlt_common.ccsds.definitions import Definitions
from tlt_gsw.archive import query as archive_query
from tlt_gsw.gui.agent_trees import AgentTrees, TreeState, status_part
from tlt_gsw.gui.archive_records import (
    AckRecord,
    Changes,
    CommandLog,
    EventRecord,
    HousekeepingSnapshot,
    PacketSummary,
    limit_event_record,
    rejection_event,
    typed_value,
)
from tlt_gsw.gui.link_counter import LinkCounter, LinkFigures
from tlt_gsw.gui.tree_definitions import TreeDefinitionFiles
from tlt_gsw.limit_events import LimitAlarms, LimitMonitor

NON_HOUSEKEEPING = ("ack", "event", "tree_status", "tree_definition")
_SECURITY_SEQ_OFFSET = PRIMARY_HEADER_LEN + TIME_LEN + 2  # after the 16-bit key id
_U64 = struct.Struct(">Q")
_SUMMARY = (
    "SELECT id, direction, recorded_at, packet_time, apid, seq_count, kind, status, detail, length(raw) "
    "FROM packets"
)
TREE_PARTS_PER_REFRESH = 256
# Copies of one shape's definition parts read at most (it is resent every few seconds).
DEFINITION_PACKETS_READ = 1024


class ArchiveModel:
    """Display state read from one archive connection (read-only); see the module docstring."""

    def __init__(
        self,
        conn: sqlite3.Connection,
        defs: Definitions,
        *,
        shapes: Mapping[str, TreeShape] | None = None,
        definition_files: TreeDefinitionFiles | None = None,
        plot_fields: Iterable[tuple[str, str]] = (),
        packet_rows: int = 500,
        event_rows: int = 1000,
        command_rows: int = 200,
        plot_window_s: float = 120.0,
        rate_window_s: float = 2.0,
        max_rows_per_refresh: int = 20000,
    ) -> None:
        self.conn = conn
        self.defs = defs
        self.agent_trees = AgentTrees(shapes, definition_files, lookup=self.archived_shape)
        self._definition_misses: dict[int, int] = {}  # shape hash -> newest definition packet then
        self.limit_monitor = LimitMonitor(defs)
        self.alarms = LimitAlarms()
        self.packet_rows = packet_rows
        self.event_rows = event_rows
        self.command_rows = command_rows
        self.plot_window_s = plot_window_s
        self.rate_window_s = rate_window_s
        self.max_rows_per_refresh = max_rows_per_refresh
        # Subsystem pages first; the CRS's link counters last (the link strip summarises them).
        self.hk_kinds = sorted(
            (k for k in defs.telemetry if k not in NON_HOUSEKEEPING), key=lambda k: k == "link_stats"
        )
        self._fdefs = {kind: {f.name: f for f in pdef.fields} for kind, pdef in defs.telemetry.items()} | {
            name: {p.name: p for p in cmd.params} for name, cmd in defs.commands.items()
        }
        # A packet kind sent once per agent (hk_ee, hk_arm_joints: field `ars`) is shown per agent.
        self.instance_field: dict[str, str] = {
            kind: next(f.name for f in pdef.fields if f.enum_name == "agent")
            for kind, pdef in defs.telemetry.items()
            if kind in self.hk_kinds and any(f.enum_name == "agent" for f in pdef.fields)
        }
        self._field_id_cache: dict[str, dict[int, str]] = {}
        self._plot_ids: dict[tuple[str, str], int | None] = {}
        self.series: dict[tuple[str, str], dict[str, deque[tuple[float, float]]]] = {}
        for kind, name in plot_fields:
            self.add_plot_field(kind, name, load=False)
        self._reset()

    # -- state ------------------------------------------------------------------------------
    def _reset(self) -> None:
        self.position = 0
        self.position_time: float | None = None
        self.link = LinkCounter(self.rate_window_s)
        self.packets: deque[PacketSummary] = deque(maxlen=self.packet_rows)
        self.housekeeping: dict[tuple[str, str], HousekeepingSnapshot] = {}  # (kind, instance)
        self.events: deque[EventRecord] = deque(maxlen=self.event_rows)
        self.commands = CommandLog(self.command_rows)
        self.agent_trees.reset()
        self.limit_monitor.levels.clear()
        self.alarms.reset()
        for key in self.series:
            self.series[key] = {}

    @property
    def trees(self) -> dict[str, TreeState]:
        """Each agent's newest tree status (see :class:`AgentTrees`)."""
        return self.agent_trees.trees

    @property
    def shapes(self) -> dict[str, TreeShape]:
        """The tree shapes known for each agent, read again when an agent's shape changes."""
        return self.agent_trees.shapes

    def head(self) -> int:
        """The id of the newest packet in the archive (0 when empty)."""
        return self.conn.execute("SELECT COALESCE(MAX(id), 0) FROM packets").fetchone()[0]

    def first(self) -> int:
        """The id of the oldest packet (0 when empty)."""
        return self.conn.execute("SELECT COALESCE(MIN(id), 0) FROM packets").fetchone()[0]

    def time_of(self, packet_id: int) -> float | None:
        row = self.conn.execute("SELECT recorded_at FROM packets WHERE id = ?", (packet_id,)).fetchone()
        return row[0] if row else None

    def id_at_time(self, t: float) -> int:
        """The newest packet recorded at or before ``t`` (0 if none)."""
        row = self.conn.execute(
            "SELECT id FROM packets WHERE recorded_at <= ? ORDER BY recorded_at DESC, id DESC LIMIT 1", (t,)
        ).fetchone()
        return row[0] if row else 0

    def query_packets(self, selection: str, limit: int) -> list[PacketSummary]:
        """The newest ``limit`` packets up to the position that match ``selection``: ``"rejected"``
        (status not ok), ``"tx"`` (sent), or a packet kind (read through the kind index)."""
        args: list[int | str]
        if selection == "rejected":
            where, args = "status != 'ok' AND id <= ?", [self.position]
            order = "id DESC"
        elif selection == "tx":
            where, args = "direction = 'tx' AND id <= ?", [self.position]
            order = "id DESC"
        else:
            where, args = "kind = ? AND id <= ?", [selection, self.position]
            order = "recorded_at DESC, id DESC"
        rows = self.conn.execute(f"{_SUMMARY} WHERE {where} ORDER BY {order} LIMIT ?", (*args, limit))
        return sorted((PacketSummary(*r) for r in rows), key=lambda p: p.id)

    def export_csv(self, kind: str, path: str | Path) -> int:
        """Write every ``kind`` packet up to the position to a CSV file (as ``tlt gsw export``
        does); return the rows written. Raises ArchiveError for a kind never recorded."""
        with open(path, "w", newline="", encoding="utf-8") as out:
            return archive_query.export_csv(self.conn, out, kind, until=self.position_time)

    def packet_raw(self, packet_id: int) -> bytes | None:
        row = self.conn.execute("SELECT raw FROM packets WHERE id = ?", (packet_id,)).fetchone()
        return bytes(row[0]) if row else None

    def packet_fields(self, packet_id: int) -> dict[str, Any]:
        """Decoded fields of one packet, typed by the definitions (empty if it has none)."""
        row = self.conn.execute("SELECT kind FROM packets WHERE id = ?", (packet_id,)).fetchone()
        if row is None or row[0] is None:
            return {}
        kind = row[0]
        fdefs = self._fdefs.get(kind, {})
        values = {}
        for fid, name in self._field_ids(kind).items():
            got = self.conn.execute(
                "SELECT value FROM fields WHERE field_id = ? AND packet_id = ?", (fid, packet_id)
            ).fetchone()
            if got is not None:
                values[name] = typed_value(fdefs.get(name), got[0])
        return values

    def link_figures(self, now: float | None = None) -> LinkFigures:
        """The counters, with rates over ``rate_window_s`` ending at ``now`` (default: the position)."""
        return self.link.figures_at(self.position_time if now is None else now)

    def archived_shape(self, shape_hash: int) -> TreeShape | None:
        """The tree shape of ``shape_hash`` from the ``tree_definition`` packets in the archive
        (anywhere in it: a definition never changes for its hash), or None. A hash not found is
        looked for again only once more definition packets have arrived."""
        newest = self.conn.execute(
            "SELECT COALESCE(MAX(id), 0) FROM packets WHERE kind = 'tree_definition'"
        ).fetchone()[0]
        if not newest or self._definition_misses.get(shape_hash) == newest:
            return None
        names = self._field_ids("tree_definition").items()
        hash_field = next((i for i, n in names if n == "shape_hash"), None)
        ids = []
        if hash_field is not None:
            ids = [
                pid
                for (pid,) in self.conn.execute(
                    "SELECT packet_id FROM fields WHERE field_id = ? AND value = ? "
                    "ORDER BY packet_id DESC LIMIT ?",
                    (hash_field, shape_hash, DEFINITION_PACKETS_READ),
                )
            ]
        assembler = DefinitionAssembler()
        for _, fields in sorted(self._kind_fields("tree_definition", ids).items(), reverse=True):
            part = DefinitionPart.from_fields(fields)
            if part is None:
                continue
            try:
                shape = assembler.add(part)
            except StatusCodecError:
                continue  # an inconsistent set; an older copy may still make the shape
            if shape is not None:
                self._definition_misses.pop(shape_hash, None)
                return shape
        self._definition_misses[shape_hash] = newest
        return None

    # -- plots ------------------------------------------------------------------------------
    def add_plot_field(self, kind: str, name: str, *, load: bool = True) -> None:
        """Plot ``kind.name`` from now on (and, with ``load``, its window up to the position)."""
        key = (kind, name)
        if key in self.series:
            return
        self.series[key] = {}
        self._plot_ids[key] = None
        if load and self.position:
            self._load_series_window(key)

    def remove_plot_field(self, kind: str, name: str) -> None:
        self.series.pop((kind, name), None)
        self._plot_ids.pop((kind, name), None)

    def _plot_id(self, key: tuple[str, str]) -> int | None:
        if self._plot_ids.get(key) is None:
            row = self.conn.execute("SELECT id FROM field_names WHERE kind = ? AND name = ?", key).fetchone()
            self._plot_ids[key] = row[0] if row else None
        return self._plot_ids[key]

    def _read_series(self, key: tuple[str, str], lo: int, hi: int) -> int:
        fid = self._plot_id(key)
        if fid is None:
            return 0
        kind = key[0]
        instances = (
            self._field_range(kind, self.instance_field[kind], lo, hi) if kind in self.instance_field else {}
        )
        curves = self.series[key]
        added = 0
        for pid, t, value in self.conn.execute(
            "SELECT packet_id, time, value FROM fields "
            "WHERE field_id = ? AND packet_id > ? AND packet_id <= ? ORDER BY packet_id",
            (fid, lo, hi),
        ):
            if isinstance(value, int | float):
                curves.setdefault(str(instances.get(pid, "")), deque()).append((t, float(value)))
                added += 1
        if added:
            newest = max(points[-1][0] for points in curves.values() if points)
            for points in curves.values():
                while points and points[0][0] < newest - self.plot_window_s:
                    points.popleft()
        return added

    def _field_range(self, kind: str, name: str, lo: int, hi: int) -> dict[int, Any]:
        """packet id -> value of one field of ``kind`` for packets in (lo, hi]."""
        fid = next((i for i, n in self._field_ids(kind).items() if n == name), None)
        if fid is None:
            return {}
        return dict(
            self.conn.execute(
                "SELECT packet_id, value FROM fields WHERE field_id = ? AND packet_id > ? AND packet_id <= ?",
                (fid, lo, hi),
            )
        )

    def _load_series_window(self, key: tuple[str, str]) -> None:
        if self.position_time is None:
            return
        row = self.conn.execute(
            "SELECT id FROM packets WHERE recorded_at >= ? ORDER BY recorded_at LIMIT 1",
            (self.position_time - self.plot_window_s,),
        ).fetchone()
        lo = (row[0] - 1) if row else self.position
        self.series[key] = {}
        self._read_series(key, min(lo, self.position), self.position)

    # -- moving the position ----------------------------------------------------------------
    def advance(self, until: int | None = None) -> Changes:
        """Apply the packets after the position, up to ``until`` (default: the newest)."""
        changes = Changes()
        head = self.head()
        target = head if until is None else min(until, head)
        if target <= self.position:
            return changes
        lo, hi = self.position, min(target, self.position + self.max_rows_per_refresh)
        rows = [
            PacketSummary(*r)
            for r in self.conn.execute(f"{_SUMMARY} WHERE id > ? AND id <= ? ORDER BY id", (lo, hi))
        ]
        for row in rows:
            self.link.count(row.direction, row.status, row.apid, row.seq_count, row.size, row.recorded_at)
        self.packets.extend(rows)
        changes.packets = len(rows)
        by_kind: dict[str, list[int]] = {}
        for row in rows:
            if row.status != "ok" or row.kind is None:
                if row.direction == "rx":
                    changes.events.append(rejection_event(row))
                continue
            by_kind.setdefault(row.kind, []).append(row.id)
        self._apply_housekeeping({k: v for k, v in by_kind.items() if k in self.hk_kinds}, changes)
        self._apply_commands([i for name in self.defs.commands for i in by_kind.get(name, ())], changes)
        self._apply_acks(by_kind.get("ack", []), changes)
        changes.events.extend(self._events(by_kind.get("event", [])[-self.event_rows :]))
        if any(kind in self.limit_monitor.fields for kind in by_kind):
            limit_events = self.limit_monitor.read(self.conn, lo, hi)
            changes.alarms = bool(self.alarms.apply(limit_events))
            changes.events.extend(limit_event_record(e) for e in limit_events)
        changes.events.sort(key=lambda e: e.packet_id)
        self.events.extend(changes.events)
        self._apply_trees(by_kind.get("tree_status", [])[-TREE_PARTS_PER_REFRESH:], changes)
        for key in self.series:
            if self._read_series(key, lo, hi):
                changes.series.add(key)
        self.position = hi
        self.position_time = rows[-1].recorded_at if rows else self.time_of(hi)
        return changes

    def seek(self, packet_id: int) -> Changes:
        """Rebuild every display's state as of ``packet_id`` (clamped to the archive)."""
        self._reset()
        changes = Changes(reset=True)
        target = max(0, min(packet_id, self.head()))
        if target == 0:
            return changes
        t = self.time_of(target)
        if t is None:  # ids are contiguous in an archive, but be safe with a hand-edited one
            target = (
                self.conn.execute("SELECT MAX(id) FROM packets WHERE id <= ?", (target,)).fetchone()[0] or 0
            )
            if target == 0:
                return changes
            t = self.time_of(target)
        self.position, self.position_time = target, t
        rejected: deque[EventRecord] = deque(maxlen=self.event_rows)
        for pid, direction, status, apid, seq, size, recorded, kind, detail in self.conn.execute(
            "SELECT id, direction, status, apid, seq_count, length(raw), recorded_at, kind, "
            "CASE WHEN status != 'ok' THEN detail END FROM packets WHERE id <= ? ORDER BY id",
            (target,),
        ):
            self.link.count(direction, status, apid, seq, size, recorded)
            if direction == "rx" and (status != "ok" or kind is None):
                rejected.append(
                    EventRecord(pid, recorded, "warning", "gsw", "DATAGRAM_REJECTED", status, detail or "")
                )
        rows = self.conn.execute(
            f"{_SUMMARY} WHERE id <= ? ORDER BY id DESC LIMIT ?", (target, self.packet_rows)
        )
        self.packets.extend(PacketSummary(*r) for r in reversed(rows.fetchall()))
        changes.packets = len(self.packets)

        def newest(kind: str, limit: int, since: float | None = None) -> list[int]:
            sql = "SELECT id FROM packets WHERE kind = ? AND recorded_at <= ? AND id <= ?"
            args: list[Any] = [kind, t, target]
            if since is not None:
                sql += " AND recorded_at >= ?"
                args.append(since)
            sql += " ORDER BY recorded_at DESC, id DESC LIMIT ?"
            return sorted(r[0] for r in self.conn.execute(sql, (*args, limit)))

        self._apply_housekeeping(
            {k: newest(k, 64 if k in self.instance_field else 1) for k in self.hk_kinds}, changes
        )
        sent = sorted(i for name in self.defs.commands for i in newest(name, self.command_rows))
        sent = sent[-self.command_rows :]
        self._apply_commands(sent, changes)
        oldest = self.time_of(sent[0]) if sent else t
        self._apply_acks(newest("ack", 4 * self.command_rows, since=oldest), changes)
        limit_events = self.limit_monitor.read(self.conn, 0, target)
        self.alarms.apply(limit_events)
        events = list(self._events(newest("event", self.event_rows))) + list(rejected)
        events += [limit_event_record(e) for e in limit_events[-self.event_rows :]]
        events.sort(key=lambda e: e.packet_id)
        self.events.extend(events)
        changes.events = list(self.events)
        self._apply_trees(newest("tree_status", TREE_PARTS_PER_REFRESH), changes)
        for key in self.series:
            self._load_series_window(key)
            changes.series.add(key)
        return changes

    # -- per-packet work --------------------------------------------------------------------
    def _field_ids(self, kind: str) -> dict[int, str]:
        ids = self._field_id_cache.get(kind)
        if not ids:
            ids = dict(
                self.conn.execute("SELECT id, name FROM field_names WHERE kind = ? ORDER BY id", (kind,))
            )
            self._field_id_cache[kind] = ids
        return ids

    def _kind_fields(self, kind: str, ids: list[int]) -> dict[int, dict[str, Any]]:
        """Fields of the packets ``ids`` (all of ``kind``): one range read per field of the kind."""
        if not ids:
            return {}
        wanted = set(ids)
        lo, hi = min(ids) - 1, max(ids)
        fdefs = self._fdefs.get(kind, {})
        out: dict[int, dict[str, Any]] = {i: {} for i in ids}
        for fid, name in self._field_ids(kind).items():
            fd = fdefs.get(name)
            for pid, value in self.conn.execute(
                "SELECT packet_id, value FROM fields WHERE field_id = ? AND packet_id > ? AND packet_id <= ?",
                (fid, lo, hi),
            ):
                if pid in wanted:
                    out[pid][name] = typed_value(fd, value)
        return out

    def _apply_housekeeping(self, ids_by_kind: Mapping[str, list[int]], changes: Changes) -> None:
        """Keep the newest packet of each kind (of each agent, for per-agent kinds) among ``ids``."""
        for kind, ids in ids_by_kind.items():
            if not ids:
                continue
            newest: dict[str, int] = {"": max(ids)}
            if kind in self.instance_field:
                instances = self._field_range(kind, self.instance_field[kind], min(ids) - 1, max(ids))
                newest = {}
                for pid in sorted(ids):
                    newest[str(instances.get(pid, ""))] = pid
            fields = self._kind_fields(kind, list(newest.values()))
            for instance, pid in newest.items():
                row = self.conn.execute(
                    "SELECT packet_time, recorded_at FROM packets WHERE id = ?", (pid,)
                ).fetchone()
                self.housekeeping[(kind, instance)] = HousekeepingSnapshot(
                    kind, pid, row[0], row[1], fields[pid]
                )
            changes.kinds.add(kind)

    def _apply_commands(self, ids: list[int], changes: Changes) -> None:
        if not ids:
            return
        ids = sorted(ids)[-self.command_rows :]
        marks = ",".join("?" * len(ids))
        heads = self.conn.execute(
            f"SELECT id, kind, recorded_at, substr(raw, {_SECURITY_SEQ_OFFSET + 1}, 8) FROM packets "
            f"WHERE id IN ({marks}) AND direction = 'tx'",
            ids,
        ).fetchall()
        by_kind: dict[str, list[int]] = {}
        for pid, kind, _, _ in heads:
            by_kind.setdefault(kind, []).append(pid)
        params: dict[int, dict[str, Any]] = {}
        for kind, kind_ids in by_kind.items():
            params.update(self._kind_fields(kind, kind_ids))
        for pid, kind, recorded, seq_bytes in sorted(heads):
            if seq_bytes is None or len(seq_bytes) != 8:
                continue
            (seq,) = _U64.unpack(bytes(seq_bytes))
            self.commands.sent(seq, kind, params.get(pid, {}), recorded, pid)
            changes.commands.add(seq)

    def _apply_acks(self, ids: list[int], changes: Changes) -> None:
        for pid, f in sorted(self._kind_fields("ack", ids).items()):
            seq = f.get("security_seq")
            if seq is None:
                continue
            time_row = self.conn.execute("SELECT recorded_at FROM packets WHERE id = ?", (pid,)).fetchone()
            ack = AckRecord(
                str(f.get("stage", "?")),
                str(f.get("reason", "")),
                str(f.get("detail", "")),
                time_row[0] if time_row else 0.0,
                pid,
            )
            self.commands.acked(int(seq), str(f.get("command", "?")), ack)
            changes.commands.add(int(seq))

    def _events(self, ids: list[int]) -> list[EventRecord]:
        fields = self._kind_fields("event", ids)
        if not fields:
            return []
        marks = ",".join("?" * len(fields))
        times = dict(
            self.conn.execute(f"SELECT id, recorded_at FROM packets WHERE id IN ({marks})", list(fields))
        )
        return [
            EventRecord(
                pid,
                times.get(pid, 0.0),
                str(f.get("severity", "info")),
                str(f.get("source", "")),
                str(f.get("code", "")),
                str(f.get("reason", "none")),
                str(f.get("text", "")),
            )
            for pid, f in sorted(fields.items())
        ]

    def _apply_trees(self, ids: list[int], changes: Changes) -> None:
        """Decode the newest tick of each agent among the parts ``ids`` (see :class:`AgentTrees`)."""
        fields = sorted(self._kind_fields("tree_status", ids).items())
        parts = [(pid, part) for pid, f in fields if (part := status_part(f)) is not None]
        changes.trees |= self.agent_trees.apply(parts)


__all__ = ["ArchiveModel"]
