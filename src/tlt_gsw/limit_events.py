"""Limit crossings of telemetry fields as events and alarms, as operators know them from COSMOS and
Yamcs: computed from the archive (Fig. 6), so the GUI, its replay and ``tlt gsw summary`` agree.

A field with ``limits`` in the definitions file is nominal, yellow (outside its yellow range) or
red (outside its red range). Every change of that level, per field and per agent for a packet sent
once per agent, is a :class:`LimitEvent` that names the value and the limit crossed (or says the
value is back within limits). :class:`LimitAlarms` folds the events into alarms: an alarm opens
when a field leaves its limits, follows it while it stays out (its worst level and value kept),
and is *cleared* when the field is back within limits. The GUI shows an alarm until the operator
acknowledged it *and* it is cleared; an alarm that gets worse after its acknowledgement (yellow to
red) asks for it again.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from tlt_common.ccsds.definitions import Definitions, FieldDef

LEVEL_RANK = {None: 0, "yellow": 1, "red": 2}
CODES = {None: "LIMIT_OK", "yellow": "LIMIT_YELLOW", "red": "LIMIT_RED"}
SEVERITY = {None: "info", "yellow": "warning", "red": "error"}

Key = tuple[str, str, str]  # (packet kind, instance (agent) or "", field)


def _number(value: float) -> str:
    return f"{value:.6g}"


@dataclass(frozen=True)
class LimitEvent:
    """A field's limit level changed with the packet ``packet_id`` (``level`` None: back within
    limits). ``limit`` is the range the value lies outside (for None, the range it is back in)."""

    packet_id: int
    time: float
    kind: str
    instance: str
    field: str
    level: str | None
    previous: str | None
    value: float
    limit: tuple[float, float]
    unit: str = ""

    @property
    def key(self) -> Key:
        return self.kind, self.instance, self.field

    @property
    def name(self) -> str:
        """``kind.field`` and, for a packet sent once per agent, the agent."""
        return f"{self.kind}.{self.field}" + (f" ({self.instance})" if self.instance else "")

    @property
    def code(self) -> str:
        return CODES[self.level]

    @property
    def severity(self) -> str:
        return SEVERITY[self.level]

    def value_text(self) -> str:
        return _number(self.value) + (f" {self.unit}" if self.unit else "")

    def limit_text(self) -> str:
        return f"[{_number(self.limit[0])}, {_number(self.limit[1])}]"

    def text(self) -> str:
        if self.level is None:
            return f"{self.name} = {self.value_text()}: back within limits {self.limit_text()}"
        return f"{self.name} = {self.value_text()}: outside its {self.level} limits {self.limit_text()}"


class LimitMonitor:
    """The limit level of every limited field, fed one decoded packet at a time in archive order."""

    def __init__(self, defs: Definitions) -> None:
        self.fields: dict[str, list[FieldDef]] = {}
        self.instance_field: dict[str, str] = {}
        for kind, pdef in defs.telemetry.items():
            limited = [f for f in pdef.fields if f.limits is not None]
            if not limited:
                continue
            self.fields[kind] = limited
            agent = next((f.name for f in pdef.fields if f.enum_name == "agent"), None)
            if agent is not None:
                self.instance_field[kind] = agent
        self.levels: dict[Key, str | None] = {}

    def feed(self, packet_id: int, time: float, kind: str, fields: Mapping[str, Any]) -> list[LimitEvent]:
        """The limit events of one packet (none for a kind without limits)."""
        limited = self.fields.get(kind)
        if not limited:
            return []
        instance = self.instance_field.get(kind)
        where = str(fields.get(instance, "")) if instance else ""
        events = []
        for fd in limited:
            value = fields.get(fd.name)
            if value is None:
                continue
            limits = fd.limits
            assert limits is not None
            level = limits.classify(value)
            if level is None and not isinstance(value, int | float):
                continue  # not a number: no level to judge
            key = (kind, where, fd.name)
            previous = self.levels.get(key)
            if level == previous:
                continue
            self.levels[key] = level
            shown = level or previous  # back in: the range it left
            limit = getattr(limits, shown) if shown else None
            if limit is None:
                continue
            events.append(
                LimitEvent(
                    packet_id, time, kind, where, fd.name, level, previous, float(value), limit, fd.unit
                )
            )
        return events

    def read(self, conn: sqlite3.Connection, after: int = 0, until: int | None = None) -> list[LimitEvent]:
        """Feed every archived packet of a limited kind with ``after < id <= until`` (in packet
        order) and return their events; one range read of the fields b-tree per kind."""
        names: dict[int, tuple[str, str]] = {}
        for fid, kind, name in conn.execute("SELECT id, kind, name FROM field_names"):
            if kind in self.fields and (
                any(f.name == name for f in self.fields[kind]) or self.instance_field.get(kind) == name
            ):
                names[fid] = (kind, name)
        if not names:
            return []
        high = (
            until
            if until is not None
            else conn.execute("SELECT COALESCE(MAX(id), 0) FROM packets").fetchone()[0]
        )
        packets: dict[int, tuple[str, float, dict[str, Any]]] = {}
        marks = ",".join("?" * len(names))
        for fid, pid, t, value in conn.execute(
            f"SELECT field_id, packet_id, time, value FROM fields "
            f"WHERE field_id IN ({marks}) AND packet_id > ? AND packet_id <= ?",
            (*names, after, high),
        ):
            kind, name = names[fid]
            packets.setdefault(pid, (kind, t, {}))[2][name] = value
        events = []
        for pid in sorted(packets):
            kind, t, values = packets[pid]
            events.extend(self.feed(pid, t, kind, values))
        if events:  # the time the GSW received each one (packet time is the CRS's clock)
            ids = sorted({e.packet_id for e in events})
            received = dict(
                conn.execute(
                    f"SELECT id, recorded_at FROM packets WHERE id IN ({','.join('?' * len(ids))})", ids
                )
            )
            events = [dataclasses.replace(e, time=received.get(e.packet_id, e.time)) for e in events]
        return events


@dataclass
class LimitAlarm:
    """One stay of a field outside its limits: opened by ``raised``, its ``worst`` event and its
    ``latest`` level change so far, ``cleared`` once back within limits."""

    raised: LimitEvent
    worst: LimitEvent
    latest: LimitEvent
    cleared: LimitEvent | None = None
    acknowledged: bool = False

    @property
    def id(self) -> tuple[Key, int]:
        """Stable across re-reads of the archive: the field and the packet that raised it."""
        return self.raised.key, self.raised.packet_id

    @property
    def active(self) -> bool:
        return self.cleared is None

    @property
    def shown(self) -> bool:
        """Shown to the operator until acknowledged and cleared."""
        return not (self.acknowledged and not self.active)


@dataclass
class LimitAlarms:
    """Alarms from limit events, and the operator's acknowledgements (kept by alarm id, so a
    re-read of the archive, e.g. a replay seek, keeps them)."""

    alarms: list[LimitAlarm] = field(default_factory=list)
    acknowledged: set[tuple[Key, int]] = field(default_factory=set)
    _open: dict[Key, LimitAlarm] = field(default_factory=dict)

    def reset(self) -> None:
        """Forget the alarms (not the acknowledgements)."""
        self.alarms, self._open = [], {}

    def apply(self, events: Iterable[LimitEvent]) -> list[LimitAlarm]:
        """Fold ``events`` in; return the alarms they opened or changed."""
        touched: dict[int, LimitAlarm] = {}
        for event in events:
            alarm = self._open.get(event.key)
            if event.level is None:
                if alarm is not None:
                    alarm.cleared = alarm.latest = event
                    del self._open[event.key]
                    touched[id(alarm)] = alarm
                continue
            if alarm is None:
                alarm = LimitAlarm(event, event, event)
                alarm.acknowledged = alarm.id in self.acknowledged
                self._open[event.key] = alarm
                self.alarms.append(alarm)
            else:
                alarm.latest = event
                if LEVEL_RANK[event.level] > LEVEL_RANK[alarm.worst.level]:
                    alarm.worst = event  # worse than what was acknowledged: ask again
                    alarm.acknowledged = False
                    self.acknowledged.discard(alarm.id)
            touched[id(alarm)] = alarm
        return list(touched.values())

    def acknowledge(self, alarm: LimitAlarm) -> None:
        alarm.acknowledged = True
        self.acknowledged.add(alarm.id)

    def shown(self) -> list[LimitAlarm]:
        return [a for a in self.alarms if a.shown]

    def unacknowledged(self) -> list[LimitAlarm]:
        return [a for a in self.alarms if not a.acknowledged]


def limit_alarms(conn: sqlite3.Connection, defs: Definitions, after: int = 0) -> list[LimitAlarm]:
    """Every alarm of the archive after packet id ``after`` (the summary's list)."""
    alarms = LimitAlarms()
    alarms.apply(LimitMonitor(defs).read(conn, after))
    return alarms.alarms


__all__ = ["Key", "LimitAlarm", "LimitAlarms", "LimitEvent", "LimitMonitor", "limit_alarms"]
