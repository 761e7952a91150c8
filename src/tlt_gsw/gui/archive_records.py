"""The records the GSW displays are drawn from, as :class:`~tlt_gsw.gui.archive_model.ArchiveModel`
builds them from the telemetry archive: packets, commands with their acknowledgements, events
(limit crossings among them), housekeeping snapshots, and what one refresh changed."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from tlt_common.ccsds.definitions import FieldDef
from tlt_gsw.limit_events import LimitEvent


@dataclass(frozen=True)
class PacketSummary:
    """One archived packet without its bytes (the packet view reads those on demand)."""

    id: int
    direction: str
    recorded_at: float
    packet_time: float | None
    apid: int | None
    seq_count: int | None
    kind: str | None
    status: str
    detail: str | None
    size: int


@dataclass(frozen=True)
class AckRecord:
    """One acknowledgement stage of a command."""

    stage: str  # accepted, rejected, completed, failed
    reason: str
    detail: str
    time: float
    packet_id: int


@dataclass
class CommandRecord:
    """A command sent (a ``tx`` packet) and the acknowledgements that answer it."""

    security_seq: int
    name: str
    params: dict[str, Any]
    sent_at: float | None  # None: an ack for a command that is not in the archive (another GSW)
    packet_id: int | None
    acks: list[AckRecord] = field(default_factory=list)
    # Replayed copies of this command the CRS rejected: their acks answer the copies, not it.
    replays_rejected: int = 0

    @property
    def last_stage(self) -> str:
        return self.acks[-1].stage if self.acks else "sent"


class CommandLog(dict[int, CommandRecord]):
    """The commands sent and their acknowledgements, by security sequence number, the newest
    ``rows`` kept (in the order first seen)."""

    def __init__(self, rows: int) -> None:
        super().__init__()
        self.rows = rows

    def record(self, seq: int, name: str) -> CommandRecord:
        """The record of command ``seq``, new if none yet (its ack may come before it)."""
        if seq not in self:
            self[seq] = CommandRecord(seq, name, {}, None, None)
        return self[seq]

    def sent(self, seq: int, name: str, params: dict[str, Any], sent_at: float, packet_id: int) -> None:
        record = self.record(seq, name)
        record.name, record.params, record.sent_at, record.packet_id = name, params, sent_at, packet_id
        self._trim()

    def acked(self, seq: int, name: str, ack: AckRecord) -> None:
        """``ack`` for command ``seq``; a ``replay`` rejection of a command already answered answers
        a replayed copy: counted on the command, not taken as its stage."""
        record = self.record(seq, name)
        if ack.reason == "replay" and record.acks:
            record.replays_rejected += 1
        else:
            record.acks.append(ack)
        self._trim()

    def _trim(self) -> None:
        while len(self) > self.rows:
            self.pop(next(iter(self)))


@dataclass(frozen=True)
class EventRecord:
    """An event for operators: a CRS ``event`` packet, or a datagram the GSW rejected."""

    packet_id: int
    time: float
    severity: str
    source: str
    code: str
    reason: str
    text: str


@dataclass(frozen=True)
class HousekeepingSnapshot:
    """The newest packet of one housekeeping kind."""

    kind: str
    packet_id: int
    time: float
    recorded_at: float
    fields: dict[str, Any]


@dataclass
class Changes:
    """What one advance or seek changed, so the views redraw only that."""

    reset: bool = False
    packets: int = 0
    kinds: set[str] = field(default_factory=set)
    events: list[EventRecord] = field(default_factory=list)
    commands: set[int] = field(default_factory=set)
    trees: set[str] = field(default_factory=set)
    series: set[tuple[str, str]] = field(default_factory=set)
    alarms: bool = False  # a limit alarm opened or changed

    def __bool__(self) -> bool:
        return bool(
            self.reset or self.packets or self.kinds or self.events or self.commands or self.trees
            or self.series or self.alarms
        )  # fmt: skip


def limit_event_record(event: LimitEvent) -> EventRecord:
    """The event shown for a field crossing a limit (or back within its limits)."""
    return EventRecord(event.packet_id, event.time, event.severity, "gsw", event.code, "none", event.text())


def rejection_event(row: PacketSummary) -> EventRecord:
    """The event shown for a datagram the GSW rejected."""
    return EventRecord(
        row.id, row.recorded_at, "warning", "gsw", "DATAGRAM_REJECTED", row.status, row.detail or ""
    )


def typed_value(fd: FieldDef | None, value: Any) -> Any:
    """A stored field value as the definitions type it (SQLite keeps booleans as 0/1 and u64 above
    2^63 - 1 as text)."""
    if fd is None or value is None:
        return value
    if fd.type == "bool":
        return bool(value)
    if fd.type == "u64" and isinstance(value, str):
        return int(value)
    return value


__all__ = [
    "AckRecord",
    "Changes",
    "CommandLog",
    "CommandRecord",
    "EventRecord",
    "HousekeepingSnapshot",
    "PacketSummary",
    "limit_event_record",
    "rejection_event",
    "typed_value",
]
