"""The end-of-mission summary, computed from the telemetry archive alone (``tlt gsw summary``).

Everything here is a query on an archive the GSW recorded (Fig. 6), so the summary of a run can be
printed at its end by the mission job or afterwards from any archive file. It reads:

* ``mission_step`` (sent by the CRS whenever its tree moves to another step): which step of which
  member ran when, in the CRS's ROS time (simulated time on the twin) and in the archive's
  receive time (wall time), the bays built, members placed and parts discarded;
* ``hk_mission`` (1 Hz): bays and members totals, run state, the standing fault;
* ``hk_tower``: the state of every member;
* ``event``: ``INSPECTION_PASSED`` / ``INSPECTION_FAILED`` (one per part presented),
  ``BAY_INSPECTION_PASSED`` / ``BAY_INSPECTION_FAILED``, ``CRS_FAULT``, ``FAULT_CLEARED``, ``CRS_UP``;
* commands sent (``tx``) and their ``ack`` packets: what the operator did about a fault;
* every field with limits in the definitions (:mod:`tlt_gsw.limit_events`): each time one left
  its limits, its worst level, value and limit, and when it came back (or that it did not).

An ack is matched to the command it answers by the security sequence number. A ``replay``
rejection of a number whose command was already acknowledged answers a copy of that packet that
someone replayed to the CRS, not the command: it is counted apart (``replays_rejected``) and never
changes the command's outcome. Likewise an ack that arrives after a command's final stage does not
move it back.

A step's span runs from its ``mission_step`` packet to the next one. A bay's time runs from its
first step to the first packet saying it is built. An event's simulated time is that of the step
in progress when it arrived.
"""

from __future__ import annotations

import itertools
import re
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tlt_common.ccsds.definitions import Definitions, load_definitions
from tlt_gsw.archive import query as archive_query
from tlt_gsw.limit_events import LimitAlarm, limit_alarms

# Kinds the summary reads; everything else in the archive is left alone.
KINDS = ("mission_step", "hk_mission", "hk_tower", "event", "ack")
# hk_tower member states (tlt_interfaces/MemberState).
STATE_NAMES = ("not placed", "placed", "riveted", "inspected")
FOUNDATION = "foundation"


@dataclass(frozen=True)
class Record:
    """One archived packet with its decoded fields."""

    id: int
    direction: str
    recorded_at: float
    kind: str
    fields: dict[str, Any]


@dataclass(frozen=True)
class StepSpan:
    """One step of the CRS tree as it ran: ``member`` is the member (or phase) it worked on."""

    bay: int
    member: str
    step: str
    sim_start: float
    sim_end: float
    wall_start: float
    wall_end: float

    @property
    def group(self) -> str:
        """The timeline group: ``bay <n>`` or ``foundation``."""
        return FOUNDATION if self.member.startswith(f"{FOUNDATION}/") else f"bay {self.bay}"


@dataclass
class PhaseTimes:
    """Sim and wall time of one bay (or of the foundation rivets)."""

    name: str
    sim_start: float
    wall_start: float
    sim_end: float
    wall_end: float
    complete: bool = False

    @property
    def sim_s(self) -> float:
        return self.sim_end - self.sim_start

    @property
    def wall_s(self) -> float:
        return self.wall_end - self.wall_start


@dataclass
class Fault:
    """A fault the CRS raised, and what cleared it (empty while it stands)."""

    reason: str
    raised_wall: float
    raised_sim: float | None
    cleared_wall: float | None = None
    cleared_sim: float | None = None
    cleared_by: str = ""

    @property
    def standing(self) -> bool:
        return self.cleared_wall is None


@dataclass
class Inspection:
    """One inspection verdict: a part presented for ``target`` (a member id) or a bay."""

    target: str
    passed: bool
    detail: str
    wall: float
    sim: float | None
    bay_inspection: bool = False


@dataclass
class CommandRecord:
    name: str
    params: dict[str, Any]
    sent_at: float
    stage: str = "sent"  # the latest ack stage
    reason: str = ""
    detail: str = ""
    replays_rejected: int = 0  # replayed copies of this command the CRS rejected


@dataclass
class MissionSummary:
    """What the summary says; :func:`format_summary` writes it as text."""

    archive: str
    tower_built: bool = False
    run_state: str = "unknown"
    bays_total: int = 0
    bays_built: int = 0
    members_total: int = 0
    members_placed: int = 0
    members_riveted: int = 0
    member_states: dict[str, int] = field(default_factory=dict)  # state name -> count (hk_tower)
    members_by_group: dict[str, list[str]] = field(default_factory=dict)  # members worked on
    parts_discarded: int = 0
    inspections: list[Inspection] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
    phases: list[PhaseTimes] = field(default_factory=list)
    steps: list[StepSpan] = field(default_factory=list)
    commands: list[CommandRecord] = field(default_factory=list)
    limit_alarms: list[LimitAlarm] = field(default_factory=list)  # each stay out of limits
    sim_start: float | None = None
    sim_end: float | None = None
    wall_start: float | None = None
    wall_end: float | None = None
    packets: int = 0

    def inspection_counts(self, bay_inspection: bool = False) -> tuple[int, int]:
        """(passed, failed) of the part (or bay) inspections."""
        chosen = [i for i in self.inspections if i.bay_inspection == bay_inspection]
        return sum(i.passed for i in chosen), sum(not i.passed for i in chosen)

    @property
    def standing_fault(self) -> Fault | None:
        return next((f for f in reversed(self.faults) if f.standing), None)


def load_records(conn: sqlite3.Connection, kinds: tuple[str, ...] = KINDS, after: int = 0) -> list[Record]:
    """Every accepted packet of ``kinds`` and every command sent after packet id ``after``, with
    fields, in archive order.

    Reads each field's range of the fields b-tree (clustered by field id) rather than scanning.
    """
    kind_list = ",".join("?" * len(kinds))
    rows = conn.execute(
        f"SELECT id, direction, recorded_at, kind FROM packets WHERE id > ? AND status = 'ok' AND "
        f"(kind IN ({kind_list}) OR (direction = 'tx' AND packet_type = 'tc')) ORDER BY id",
        (after, *kinds),
    ).fetchall()
    fields: dict[int, dict[str, Any]] = {row[0]: {} for row in rows}
    wanted = {row[3] for row in rows}
    for field_id, kind, name in conn.execute("SELECT id, kind, name FROM field_names").fetchall():
        if kind not in wanted:
            continue
        for packet_id, value in conn.execute(
            "SELECT packet_id, value FROM fields WHERE field_id = ? ORDER BY packet_id", (field_id,)
        ):
            if packet_id in fields:
                fields[packet_id][name] = value
    return [Record(r[0], r[1], r[2], r[3], fields[r[0]]) for r in rows]


def _is_true(value: Any) -> bool:
    return value in (1, True, "1", "true", "True")


def _clearing_action(command: CommandRecord) -> str | None:
    """How an operator's command counts as clearing a fault (None: it does not, or was refused)."""
    if command.stage in ("rejected", "failed"):
        return None
    if command.name == "set_blackboard_value" and command.params.get("key") == "clear_fault":
        if _is_true(command.params.get("value")):
            return "operator set clear_fault = true (Set Blackboard Value)"
        return None
    if command.name == "resume":
        return "operator Resume"
    if command.name == "start":
        return "operator Start"
    if command.name == "set_actuator_state":
        return (
            f"operator Set Actuator State {command.params.get('actuator')} -> {command.params.get('state')}"
        )
    return None


_BAY_NUMBER = re.compile(r"bay (\d+)")
_FINAL_STAGES = ("rejected", "completed", "failed")


def summarize(
    conn: sqlite3.Connection, archive: str = "", after: int = 0, defs: Definitions | None = None
) -> MissionSummary:
    """Compute the summary of the archive ``conn`` from packet id ``after`` on (0: all of it; an
    archive kept across runs holds earlier runs' packets before a job's first); ``defs`` (default:
    the project's definitions file) give the fields' limits."""
    summary = MissionSummary(archive=archive)
    summary.limit_alarms = limit_alarms(conn, defs or load_definitions(), after)
    records = load_records(conn, after=after)
    summary.packets = conn.execute("SELECT COUNT(*) FROM packets WHERE id > ?", (after,)).fetchone()[0]
    if records:
        summary.wall_start, summary.wall_end = records[0].recorded_at, records[-1].recorded_at
    by_security_seq: dict[int, CommandRecord] = {}
    last_step: Record | None = None
    open_fault: Fault | None = None
    commands_since_fault: list[CommandRecord] = []
    phases: dict[str, PhaseTimes] = {}
    bays_built_seen = 0

    def sim_now() -> float | None:
        return float(last_step.fields["sim_time"]) if last_step is not None else None

    def clear(record: Record, how: str, by_command: bool = True) -> None:
        nonlocal open_fault
        assert open_fault is not None
        actions = (_clearing_action(c) for c in reversed(commands_since_fault)) if by_command else ()
        action = next((a for a in actions if a), None)
        open_fault.cleared_wall = record.recorded_at
        open_fault.cleared_sim = sim_now()
        open_fault.cleared_by = action or how
        open_fault = None

    def raise_fault(record: Record, reason: str) -> None:
        nonlocal open_fault
        open_fault = Fault(reason, record.recorded_at, sim_now())
        summary.faults.append(open_fault)
        commands_since_fault.clear()

    pending_step: Record | None = None
    for record in records:
        f = record.fields
        if record.direction == "tx":
            params = {k: v for k, v in f.items()}
            command = CommandRecord(record.kind, params, record.recorded_at)
            summary.commands.append(command)
            seq = conn.execute("SELECT raw FROM packets WHERE id = ?", (record.id,)).fetchone()
            security_seq = int.from_bytes(seq[0][15:23], "big") if seq and len(seq[0]) >= 23 else None
            if security_seq is not None:
                by_security_seq[security_seq] = command
            if open_fault is not None:
                commands_since_fault.append(command)
            continue
        if record.kind == "ack":
            acked = by_security_seq.get(int(f.get("security_seq", -1)))
            if acked is None:
                continue
            if f["reason"] == "replay" and acked.stage != "sent":
                acked.replays_rejected += 1
            elif acked.stage not in _FINAL_STAGES:
                acked.stage, acked.reason, acked.detail = f["stage"], f["reason"], f["detail"]
            continue
        if record.kind == "mission_step":
            if summary.sim_start is None:
                summary.sim_start = float(f["sim_time"])
            summary.sim_end = float(f["sim_time"])
            if pending_step is not None:
                _close_step(summary, pending_step, record)
            pending_step = record if f["step"] else None
            last_step = record
            summary.parts_discarded = int(f["parts_discarded"])
            summary.members_placed = max(summary.members_placed, int(f["members_placed"]))
            summary.run_state = f["run_state"]
            _track_phase(phases, record)
            built = int(f["bays_built"])
            for bay in range(bays_built_seen + 1, built + 1):
                phase = phases.get(f"bay {bay}")
                if phase is not None and not phase.complete:
                    phase.sim_end, phase.wall_end = float(f["sim_time"]), record.recorded_at
                    phase.complete = True
            bays_built_seen = max(bays_built_seen, built)
            if f["run_state"] == "done":
                summary.tower_built = True
                foundation = phases.get(FOUNDATION)
                if foundation is not None:
                    foundation.sim_end, foundation.wall_end = float(f["sim_time"]), record.recorded_at
                    foundation.complete = True
            if open_fault is not None and f["run_state"] in ("running", "done"):
                clear(record, "fault no longer reported")
            continue
        if record.kind == "hk_mission":
            summary.bays_total = int(f["bays_total"])
            summary.bays_built = max(summary.bays_built, int(f["bays_built"]))
            summary.members_total = int(f["members_total"])
            summary.members_placed = max(summary.members_placed, int(f["members_placed"]))
            summary.members_riveted = max(summary.members_riveted, int(f["members_riveted"]))
            summary.run_state = f["run_state"]
            if f["run_state"] == "done":
                summary.tower_built = True
            if f["fault"] and open_fault is None:
                raise_fault(record, f["fault"])
            elif not f["fault"] and open_fault is not None and f["run_state"] != "paused":
                clear(record, "fault no longer reported")
            continue
        if record.kind == "hk_tower":
            states = unpack_member_states(f["member_states"], int(f["member_count"]))
            summary.member_states = {name: sum(s == i for s in states) for i, name in enumerate(STATE_NAMES)}
            continue
        # events
        code, text = f["code"], f["text"]
        if code in ("INSPECTION_PASSED", "INSPECTION_FAILED"):
            target, _, detail = text.partition(": ")
            summary.inspections.append(
                Inspection(target, code == "INSPECTION_PASSED", detail, record.recorded_at, sim_now())
            )
        elif code in ("BAY_INSPECTION_PASSED", "BAY_INSPECTION_FAILED"):
            target = text.split(" passed")[0].split(" failed")[0]
            summary.inspections.append(
                Inspection(target, code == "BAY_INSPECTION_PASSED", text, record.recorded_at, sim_now(), True)
            )
        elif code == "CRS_FAULT":
            if open_fault is not None and open_fault.reason == text:
                continue  # the same fault, already seen in hk_mission
            if open_fault is not None:
                clear(record, "replaced by another fault", by_command=False)
            raise_fault(record, text)
        elif code == "FAULT_CLEARED" and open_fault is not None:
            if text.startswith("operator"):
                clear(record, "operator clear_fault (FAULT_CLEARED event; the command is not archived)")
            else:  # a fault that clears itself, e.g. "lifter link back, the build goes on (was: ...)"
                clear(record, text.split(" (was:")[0], by_command=False)
        elif code == "CRS_UP" and open_fault is not None:
            clear(record, "CRS restarted", by_command=False)  # a restarted CRS starts without it
    if pending_step is not None:
        _close_step(summary, pending_step, pending_step)
    summary.phases = sorted(phases.values(), key=_phase_order)
    summary.bays_built = max(summary.bays_built, bays_built_seen)
    for span in summary.steps:
        members = summary.members_by_group.setdefault(span.group, [])
        # Members only (their ids have a '/'); phases such as Index Payload n are not members.
        if "/" in span.member and span.member not in members:
            members.append(span.member)
    return summary


def _close_step(summary: MissionSummary, start: Record, end: Record) -> None:
    f = start.fields
    summary.steps.append(
        StepSpan(
            int(f["bay"]),
            f["member"],
            f["step"],
            float(f["sim_time"]),
            float(end.fields["sim_time"]),
            start.recorded_at,
            end.recorded_at,
        )
    )


def _track_phase(phases: dict[str, PhaseTimes], record: Record) -> None:
    f = record.fields
    if not f["step"] or not f["member"]:
        return
    name = FOUNDATION if f["member"].startswith(f"{FOUNDATION}/") else f"bay {int(f['bay'])}"
    phase = phases.get(name)
    sim = float(f["sim_time"])
    if phase is None:
        phases[name] = PhaseTimes(name, sim, record.recorded_at, sim, record.recorded_at)
    elif not phase.complete:
        phase.sim_end, phase.wall_end = sim, record.recorded_at


def _phase_order(phase: PhaseTimes) -> tuple[int, int]:
    match = _BAY_NUMBER.fullmatch(phase.name)
    return (0, int(match.group(1))) if match else (1, 0)


def unpack_member_states(data: bytes, count: int) -> list[int]:
    """hk_tower's 2-bit states, first member in the high bits of the first byte."""
    out = []
    for i in range(count):
        byte = data[i // 4] if i // 4 < len(data) else 0
        out.append((byte >> (6 - 2 * (i % 4))) & 0b11)
    return out


def summarize_file(path: str | Path, after: int = 0, defs: Definitions | None = None) -> MissionSummary:
    """Open ``path`` read-only and summarize it from packet id ``after`` on (raises ArchiveError
    if it is not an archive)."""
    conn = archive_query.open_archive(path)
    try:
        return summarize(conn, str(path), after, defs)
    finally:
        conn.close()


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f} s"


def _limit_lines(s: MissionSummary) -> list[str]:
    """One line per stay of a field outside its limits, at its wall time since the run's start."""
    alarms = s.limit_alarms
    if not alarms:
        return ["  limits crossed:   none"]
    red = sum(a.worst.level == "red" for a in alarms)
    out = sum(a.active for a in alarms)
    head = f"  limits crossed:   {len(alarms)} ({red} red)"
    lines = [head + (f", {out} still out of limits at the end" if out else "")]
    start = s.wall_start if s.wall_start is not None else alarms[0].raised.time
    for alarm in alarms:
        worst, first = alarm.worst, alarm.raised
        text = (
            f"    [+{first.time - start:.1f} s] {worst.name}: {str(worst.level).upper()} "
            f"{worst.value_text()} outside {worst.limit_text()}"
        )
        if first is not worst:
            text += f" (first {first.level} {first.value_text()} outside {first.limit_text()})"
        if alarm.cleared is not None:
            text += f"; back within limits after {alarm.cleared.time - first.time:.1f} s"
        else:
            text += "; still out of limits at the end"
        lines.append(text)
    return lines


def format_summary(s: MissionSummary) -> str:
    """The summary as the text the mission job and ``tlt gsw summary`` print."""
    lines = [f"Mission summary ({s.archive or 'archive'}, {s.packets} packets)"]
    result = "tower built" if s.tower_built else f"tower NOT built (run state {s.run_state})"
    lines.append(f"  result:           {result}")
    lines.append(f"  bays built:       {s.bays_built}/{s.bays_total}")
    members = f"  members:          {s.members_placed}/{s.members_total} placed, {s.members_riveted} riveted"
    if s.member_states:
        members += " (last state: " + ", ".join(f"{n} {c}" for n, c in s.member_states.items() if c) + ")"
    lines.append(members)
    for group, names in s.members_by_group.items():
        lines.append(f"    {group}: {len(names)} worked on: {', '.join(names)}")
    passed, failed = s.inspection_counts()
    failed_on = [i.target for i in s.inspections if not i.passed and not i.bay_inspection]
    text = f"  part inspections: {passed} passed, {failed} failed"
    if failed_on:
        text += f" ({', '.join(failed_on)})"
    lines.append(text)
    bay_passed, bay_failed = s.inspection_counts(bay_inspection=True)
    lines.append(f"  bay inspections:  {bay_passed} passed, {bay_failed} failed")
    lines.append(f"  parts discarded:  {s.parts_discarded}")
    lines.append(f"  faults:           {len(s.faults)}")
    for fault in s.faults:
        at = f"sim {fault.raised_sim:.1f} s" if fault.raised_sim is not None else "sim -"
        lines.append(f"    [{at}] {fault.reason}")
        if fault.standing:
            lines.append("      NOT cleared")
        else:
            waited = (fault.cleared_wall or 0.0) - fault.raised_wall
            lines.append(f"      cleared by: {fault.cleared_by} (after {waited:.1f} s wall)")
    lines.append("  time:             sim        wall")
    for phase in s.phases:
        mark = "" if phase.complete else "  (not finished)"
        lines.append(f"    {phase.name:<14}{_seconds(phase.sim_s):>9}  {_seconds(phase.wall_s):>9}{mark}")
    sim_total = s.sim_end - s.sim_start if s.sim_start is not None and s.sim_end is not None else None
    wall_total = s.wall_end - s.wall_start if s.wall_start is not None and s.wall_end is not None else None
    lines.append(f"    {'whole run':<14}{_seconds(sim_total):>9}  {_seconds(wall_total):>9}")
    lines.extend(_limit_lines(s))
    refused = [c for c in s.commands if c.stage in ("rejected", "failed")]
    lines.append(f"  commands sent:    {len(s.commands)} ({len(refused)} rejected or failed)")
    # A job asks for Start again while the system comes up: one line per run of like refusals.
    for _, run in itertools.groupby(refused, key=lambda c: (c.name, c.stage, c.reason)):
        same = list(run)
        c, times = same[-1], f" {len(same)} times" if len(same) > 1 else ""
        last = "last: " if len(same) > 1 else ""
        lines.append(f"    {c.name} {c.stage}{times}: {c.reason} {last}{c.detail}".rstrip())
    replayed: dict[str, int] = {}
    for c in s.commands:
        if c.replays_rejected:
            replayed[c.name] = replayed.get(c.name, 0) + c.replays_rejected
    if replayed:
        per_command = ", ".join(f"{name} {count}" for name, count in replayed.items())
        lines.append(
            f"  replayed copies:  {sum(replayed.values())} rejected by the CRS as replays ({per_command}); "
            "their commands' outcomes stand"
        )
    return "\n".join(lines)


__all__ = [
    "CommandRecord",
    "Fault",
    "Inspection",
    "MissionSummary",
    "PhaseTimes",
    "Record",
    "StepSpan",
    "format_summary",
    "load_records",
    "summarize",
    "summarize_file",
    "unpack_member_states",
]
