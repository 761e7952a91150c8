"""What the headless mission job prints as a build goes (:mod:`tlt_gsw.mission_job`): a line when
the CRS's bay or step changes (with the time left once a member is placed: the wall time per
member so far, times the members left), the CRS tree's running node when it changes (or its
status counts), every event of severity warning or above, and each fault as it is raised or
cleared."""

from __future__ import annotations

from collections.abc import Mapping
from typing import IO, Any

from tlt_common.bt.status_codec import Reassembler, StatusCodecError, StatusPart, TreeShape, unpack_statuses
from tlt_common.ccsds.codec import Packet


class Progress:
    """Turns telemetry into progress lines: one per change of bay or step, tree or fault."""

    def __init__(self, out: IO[str], tree: TreeShape | None = None, tree_every_s: float = 5.0) -> None:
        self.out = out
        self.tree = tree
        self.tree_every_s = tree_every_s
        self._reassembler = Reassembler(tree) if tree is not None else None
        self._bay: int | None = None
        self._step: tuple[str, str] | None = None
        self._tree_line = ""
        self._tree_printed_at = -float("inf")
        self._tree_tick = -1
        self._tree_parts: dict[int, tuple[int, bytes]] = {}
        self._tree_error = ""
        self.fault = ""  # the fault standing now ("" none)
        self.fault_since: float | None = None
        self.tower_built = False
        self.sim_start: float | None = None
        self.last_mission: dict[str, Any] = {}
        self.crs_up = 0  # CRS_UP events seen: the CRS (re)started
        self.tower_reports = 0  # hk_tower packets seen
        self._first_step_at: float | None = None  # wall time of the first step line

    def say(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    def _sim(self, fields: Mapping[str, Any]) -> str:
        sim = float(fields["sim_time"])
        if self.sim_start is None:
            # Recordings, events and the summary's faults carry the CRS's own ROS time; say once
            # where this job's clock starts on it so a line here can be found there.
            self.sim_start = sim
            self.say(f"sim times below are from the CRS's ROS time {sim:.2f} s")
        return f"[sim {sim - self.sim_start:8.2f} s]"

    def packet(self, packet: Packet, now: float) -> None:
        kind, f = packet.kind, packet.fields
        if kind == "mission_step":
            if f["run_state"] == "done":
                self.tower_built = True
            if self._bay != f["bay"]:
                self._bay = f["bay"]
                self.say(f"{self._sim(f)} bay {f['bay']} (bays built {f['bays_built']})")
            step = (f["member"], f["step"])
            if step != self._step and f["step"]:
                self._step = step
                if self._first_step_at is None:
                    self._first_step_at = now
                member = f" {f['member']}:" if f["member"] and f["member"] not in f["step"] else ""
                self.say(
                    f"{self._sim(f)}   {f['run_state']:<7}{member} {f['step']}  "
                    f"(placed {f['members_placed']}, discarded {f['parts_discarded']}"
                    f"{self._time_left(int(f['members_placed']), now)})"
                )
        elif kind == "hk_mission":
            self.last_mission = dict(f)
            if f["run_state"] == "done":
                self.tower_built = True
            self._fault_state(f["fault"], now)
        elif kind == "event":
            code = f["code"]
            if code == "CRS_UP":
                self.crs_up += 1
            if code == "CRS_FAULT":
                self._fault_state(f["text"], now)
            elif code == "FAULT_CLEARED":
                self._fault_state("", now)
            if f["severity"] in ("warning", "error", "critical") or code in (
                "FAULT_CLEARED", "INSPECTION_FAILED", "BAY_INSPECTION_PASSED", "STARTED", "CRS_UP",
            ):  # fmt: skip
                self.say(f"  EVENT {f['severity'].upper()} {code}: {f['text']}")
        elif kind == "hk_tower":
            self.tower_reports += 1
        elif kind == "tree_status" and f["agent"] == "crs":
            self._tree_status(f, now)

    def _time_left(self, placed: int, now: float) -> str:
        """ ", about N min left" from the wall time per member placed so far ("" before the
        first member, or before the CRS has said how many there are)."""
        total = int(self.last_mission.get("members_total", 0))
        if not placed or placed >= total or self._first_step_at is None:
            return ""
        left = (now - self._first_step_at) / placed * (total - placed)
        return f", about {left / 60:.0f} min left" if left >= 90 else f", about {left:.0f} s left"

    def _fault_state(self, fault: str, now: float) -> None:
        if fault and not self.fault:
            self.fault, self.fault_since = fault, now
            self.say(f"  FAULT raised: {fault}")
        elif not fault and self.fault:
            self.say(f"  FAULT cleared after {now - (self.fault_since or now):.1f} s: {self.fault}")
            self.fault, self.fault_since = "", None

    def _tree_status(self, f: Mapping[str, Any], now: float) -> None:
        if self._reassembler is not None:
            part = StatusPart(
                "crs", f["shape_hash"], f["tick"], f["node_count"], f["part_index"], f["part_count"],
                f["first_node"], bytes(f["status"]),
            )  # fmt: skip
            try:
                decoded = self._reassembler.add(part)
            except StatusCodecError as exc:
                if str(exc) != self._tree_error:
                    self._tree_error = str(exc)
                    self.say(f"  tree: cannot decode ({exc})")
                return
            if decoded is None:
                return
            running = [path for path, status in decoded.nodes if status.name == "RUNNING"]
            line = " > ".join(running[-1].split("/")[-3:]) if running else "(nothing running)"
            if line != self._tree_line:
                self._tree_line = line
                self.say(f"  tree crs tick {decoded.tick_count}: {line}")
            return
        # Without the tree's definition the nodes have no names: count the statuses of a whole tick.
        if f["tick"] != self._tree_tick:
            self._tree_tick, self._tree_parts = f["tick"], {}
        self._tree_parts[f["part_index"]] = (f["first_node"], bytes(f["status"]))
        if len(self._tree_parts) < f["part_count"]:
            return
        statuses = []
        for first, data in sorted(self._tree_parts.values()):
            statuses += unpack_statuses(data, max(0, min(f["node_count"] - first, len(data) * 4)))
        counts = {name: sum(s.name == name for s in statuses) for name in ("RUNNING", "SUCCESS", "FAILURE")}
        line = ", ".join(f"{n.lower()} {c}" for n, c in counts.items())
        if line != self._tree_line and now - self._tree_printed_at >= self.tree_every_s:
            self._tree_line, self._tree_printed_at = line, now
            self.say(f"  tree crs tick {f['tick']}: {line} of {f['node_count']} nodes")


__all__ = ["Progress"]
