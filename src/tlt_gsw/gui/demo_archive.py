"""A telemetry archive of a mission in progress, for the GUI's screenshots, docs and replay tests.

``python -m tlt_gsw.gui.demo_archive OUT.sqlite [--tree-definition OUT.json] [--seconds 60]``

Every packet is a real one: telemetry built with :func:`encode_telemetry`, commands with
:func:`encode_command` under a random key, parsed back with :func:`parse_datagram` and stored by
the :class:`Recorder` exactly as the link thread stores what it receives. The story: a two-bay
tower with bay 1 built and bay 2 half done; the lifter, grippers, end effectors and arms move;
one lifter encoder drifts into its yellow and then red limit; the operator sends Start, Pause,
Resume, a refused Set Blackboard Value and a Set Actuator State; the CRS reports events; the CRS
tree status (a Fig. 13-shaped tree) is sent at 2 Hz, its definition first and every 5 s.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import py_trees
from py_trees.common import Status

from tlt_common.bt.nodes import Action, Condition
from tlt_common.bt.shape_definition import split_definition
from tlt_common.bt.status_codec import TreeShape, encode
from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import encode_command, encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import Definitions, load_definitions
from tlt_common.ccsds.sequence import SequenceCounters
from tlt_gsw.archive.recorder import Recorder
from tlt_gsw.gui.tower_layout import INSPECTED, NOT_PLACED, PLACED, RIVETED, TowerLayout, pack_member_states
from tlt_gsw.gui.tree_definitions import write_tree_definition

KEY_ID = 1


class _Step(Action):
    """A drawn action of the demo tree; its status is set by the story, never by a tick."""

    def update(self) -> Status:
        return self.status


class _Check(Condition):
    """A drawn condition of the demo tree."""

    def evaluate(self) -> bool:
        return self.status is Status.SUCCESS


def demo_tree() -> py_trees.behaviour.Behaviour:
    """A CRS-shaped tree (Fig. 13: guards, Build Tower with bays) to encode statuses from."""
    seq = py_trees.composites.Sequence
    fallback = py_trees.composites.Selector

    def bay(n: int) -> py_trees.behaviour.Behaviour:
        far = seq(f"Far Verticals {n}", memory=True, children=[
            _Step(f"Add Vertical {n} x0_y1"), _Step(f"Affix Vertical {n} x0_y1"),
            _Step(f"Add Vertical {n} x1_y0"), _Step(f"Affix Vertical {n} x1_y0"),
        ])  # fmt: skip
        near = seq(f"Near Verticals {n}", memory=True, children=[
            _Step(f"Add Vertical {n} x0_y0"), _Step(f"Add Vertical {n} x1_y1"),
        ])  # fmt: skip
        diagonals = seq(f"Diagonals {n}", memory=True, children=[
            _Step(f"Add Diagonal {n} {face}") for face in ("face_x0", "face_y0", "face_x1", "face_y1")
        ])  # fmt: skip
        build = seq(f"Build Bay {n}", memory=True, children=[
            fallback(f"Index Payload {n}", memory=True, children=[
                _Check(f"Bay {n} Indexed?"), _Step(f"Raise Payload {n}"), _Step(f"Lower Lifter {n}"),
            ]),
            _Step(f"Add Cross Frame {n}"), far, near, diagonals, _Step(f"Test Bay {n}"),
        ])  # fmt: skip
        return fallback(f"Bay {n}", memory=True, children=[_Check(f"Bay {n} Built?"), build])

    build_tower = seq("Build Tower", memory=False, children=[bay(1), bay(2), _Step("Add Foundation Rivets")])
    tower = fallback("Tower", memory=False, children=[
        _Check("Tower Built?"), build_tower, _Step("Raise Fault"),
    ])  # fmt: skip
    fault = fallback("Fault Check", memory=False, children=[_Check("No Fault?"), _Step("Wait For Help")])
    return seq("CRS", memory=False, children=[
        _Step("Initialise Blackboard"), _Step("Process Ground Command"), fault, _Check("Started?"), tower,
    ])  # fmt: skip


def set_demo_statuses(shape: TreeShape, tick: int) -> None:
    """Bay 1 built, bay 2 adding its near verticals; the running leaf alternates with ``tick``."""
    done_prefixes = (
        "Bay 1 Built?",
        "Initialise Blackboard",
        "Process Ground Command",
        "No Fault?",
        "Started?",
    )
    bay2_done = (
        "Bay 2 Indexed?", "Add Cross Frame 2", "Add Vertical 2 x0_y1", "Affix Vertical 2 x0_y1",
        "Add Vertical 2 x1_y0", "Affix Vertical 2 x1_y0", "Far Verticals 2", "Index Payload 2",
    )  # fmt: skip
    running = ("CRS", "Tower", "Build Tower", "Bay 2", "Build Bay 2", "Near Verticals 2")
    for node, behaviour in zip(shape.nodes, shape.behaviours, strict=True):
        if node.name in done_prefixes or node.name in bay2_done or node.name in ("Fault Check", "Bay 1"):
            behaviour.status = Status.SUCCESS
        elif node.name in running:
            behaviour.status = Status.RUNNING
        elif node.name in ("Tower Built?", "Bay 2 Built?"):
            behaviour.status = Status.FAILURE
        elif node.name == "Add Vertical 2 x0_y0":
            behaviour.status = Status.SUCCESS if tick % 20 >= 10 else Status.RUNNING
        elif node.name == "Add Vertical 2 x1_y1":
            behaviour.status = Status.RUNNING if tick % 20 >= 10 else Status.INVALID
        else:
            behaviour.status = Status.INVALID


@dataclass
class DemoArchive:
    """What :func:`write_demo_archive` made: the file, the tree shape and the packet count."""

    path: Path
    shape: TreeShape
    packets: int
    start: float
    end: float


class _Writer:
    """Encodes, parses and records packets with one sequence counter per APID and a fake clock."""

    def __init__(self, recorder: Recorder, defs: Definitions, keyring: KeyRing) -> None:
        self.recorder, self.defs, self.keyring = recorder, defs, keyring
        self.counters = SequenceCounters()
        self.count = 0
        self.security_seq = int(time.time() * 1e6)

    def tm(self, kind: str, values: dict[str, Any], t: float) -> None:
        raw = encode_telemetry(
            self.defs, kind, values, seq_count=self.counters.next(self.defs.packet(kind).apid), timestamp=t
        )
        self.recorder.record("rx", raw, parse_datagram(raw, self.defs), recorded_at=t)
        self.count += 1

    def tc(self, name: str, params: dict[str, Any], t: float) -> int:
        self.security_seq += 1
        raw = encode_command(
            self.defs, name, params, key_id=KEY_ID, key=self.keyring.get(KEY_ID) or b"",
            security_seq=self.security_seq, seq_count=self.counters.next(self.defs.command_apid),
            timestamp=t,
        )  # fmt: skip
        self.recorder.record("tx", raw, parse_datagram(raw, self.defs, expect="tc", keyring=self.keyring), t)
        self.count += 1
        return self.security_seq

    def ack(self, name: str, seq: int, stage: str, t: float, reason: str = "none", detail: str = "") -> None:
        self.tm("ack", {
            "command_apid": self.defs.command_apid, "command_seq_count": 0, "security_seq": seq,
            "command": name, "stage": stage, "reason": reason, "detail": detail,
        }, t)  # fmt: skip

    def event(self, severity: str, code: str, text: str, t: float, reason: str = "none") -> None:
        self.tm(
            "event", {"severity": severity, "source": "crs", "code": code, "reason": reason, "text": text}, t
        )


def write_demo_archive(
    path: str | Path,
    *,
    seconds: float = 60.0,
    start: float | None = None,
    defs: Definitions | None = None,
    tree_definition: str | Path | None = None,
    progress: Callable[[float], None] | None = None,
) -> DemoArchive:
    """Write ``seconds`` of the demo story into a new archive at ``path`` (see the module docstring)."""
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path} exists; the demo writes a new archive")
    defs = defs or load_definitions()
    start = time.time() - seconds if start is None else start
    keyring = KeyRing({KEY_ID: os.urandom(32)})
    root = demo_tree()
    shape = TreeShape.of(root)
    if tree_definition is not None:
        write_tree_definition(shape, tree_definition, agent="crs")
    layout = TowerLayout.standard(2)
    with Recorder(path) as recorder:
        w = _Writer(recorder, defs, keyring)
        commands: dict[float, tuple[str, dict[str, Any]]] = {
            2.0: ("start", {}), 12.0: ("pause", {}), 16.0: ("resume", {}),
            24.0: ("set_blackboard_value", {"key": "lifter_speed", "value": 0.5}),
            30.0: ("set_actuator_state", {"actuator": "camera_mounts", "state": "inspect_bay"}),
        }  # fmt: skip
        pending: list[tuple[float, str, int, str, str, str]] = []
        steps = int(seconds * 10)
        tick = 0
        for i in range(steps + 1):
            s = i / 10.0
            t = start + s
            for at, (name, params) in commands.items():
                if at <= s < at + 0.1:
                    seq = w.tc(name, params, t)
                    if name == "set_blackboard_value":
                        pending.append((t + 0.01, name, seq, "rejected", "bad_parameter_range",
                                        "lifter_speed: 0.5 is above the maximum 0.05"))  # fmt: skip
                        continue
                    pending.append((t + 0.01, name, seq, "accepted", "none", ""))
                    pending.append((t + 1.5, name, seq, "completed", "none", ""))
            for item in [p for p in pending if p[0] <= t]:
                pending.remove(item)
                when, name, seq, stage, reason, detail = item
                w.ack(name, seq, stage, when, reason, detail)
                if stage == "rejected":
                    w.event(
                        "warning", "COMMAND_REJECTED", f"{name} rejected: {reason}: {detail}", when, reason
                    )
            if i % 5 == 0:  # 2 Hz housekeeping
                drift = min(1.0, max(0.0, (s - 0.6 * seconds) / (0.4 * seconds)))  # 0 .. 1 in the last 40 %
                base = 0.45 + 0.35 * math.sin(s / 8.0)
                w.tm("hk_lifter", {
                    "state": "crs_control", "position_0": base, "position_1": base + 0.001,
                    "position_2": base - 0.001, "position_3": base * (1 - drift) + 2.1 * drift,
                    "velocity": int(3000 * math.cos(s / 8.0)) + (4500 if s > seconds * 0.8 else 0),
                    "limit_switches": 0, "watchdog_tripped": False, "link_ok": True,
                }, t)  # fmt: skip
                w.tm("hk_grippers", {
                    "top_engaged": 0b1111, "top_position_mean": 0.0265, "top_fault": False,
                    "active_engaged": 0b0011, "active_height": 0.3 + 0.25 * math.sin(s / 5.0),
                    "active_fault": False,
                }, t)  # fmt: skip
                for ars, phase in (("ars_x", 0.0), ("ars_y", 1.3)):
                    w.tm("hk_ee", {
                        "ars": ars, "grasp_left": 0.4, "grasp_right": 0.4,
                        "width": 0.045 + 0.04 * math.sin(s / 3.0 + phase),
                        "max_load": 0.3 + 0.3 * math.sin(s + phase), "calibrated": True,
                        "part_grasped": ars == "ars_x", "rivet_guns": 0b11, "fault": False,
                    }, t)  # fmt: skip
                    w.tm("hk_arm_joints", {
                        "ars": ars, "q0": math.sin(s / 6 + phase), "q1": -1.2 + 0.3 * math.sin(s / 4),
                        "q2": 1.5, "q3": -1.8, "q4": -1.57, "q5": 0.2 * math.cos(s / 2),
                        "protective_stop": False,
                    }, t)  # fmt: skip
                if i % 50 == 0:  # the tree's definition, as the CRS sends it (first, then every 5 s)
                    for definition_part in split_definition(shape, "crs"):
                        w.tm("tree_definition", definition_part.fields(), t)
                tick += 1
                set_demo_statuses(shape, tick)
                for part in encode(shape, agent="crs", tick_count=tick, max_status_bytes=8):
                    w.tm("tree_status", {
                        "agent": part.agent, "shape_hash": part.shape_hash, "tick": part.tick_count,
                        "node_count": part.node_count, "part_index": part.part_index,
                        "part_count": part.part_count, "first_node": part.first_node, "status": part.status,
                    }, t)  # fmt: skip
            if i % 10 == 0:  # 1 Hz mission progress and tower model
                bay2 = [PLACED] + [
                    PLACED if k < min(4, int(s / (seconds / 5))) else NOT_PLACED for k in range(8)
                ]
                if s > seconds / 2:
                    bay2[1] = bay2[2] = RIVETED  # the far verticals, affixed
                states = [INSPECTED] + [RIVETED] * 8 + bay2 + [NOT_PLACED] * 4
                w.tm("hk_mission", {
                    "run_state": "paused" if 12 <= s < 16 else ("running" if s >= 2 else "idle"),
                    "started": s >= 2, "bays_total": 2, "bays_built": 1, "current_bay": 2,
                    "members_total": len(states), "members_placed": sum(1 for x in states if x),
                    "members_riveted": sum(1 for x in states if x >= RIVETED),
                    "current_step": "Near Verticals 2: Add Vertical 2 x0_y0", "fault": "",
                }, t)  # fmt: skip
                w.tm(
                    "hk_tower",
                    {"member_count": len(layout.members), "member_states": pack_member_states(states)},
                    t,
                )
            if i % 20 == 0:
                w.tm("link_stats", {
                    "packets_rx": 6 + i // 100, "bytes_rx": 300 + 50 * (i // 100), "packets_tx": w.count,
                    "bytes_tx": 60 * w.count, "gaps": 0, "missing": 0, "crc_errors": 0,
                    "rejections": 1 if s > 24 else 0, "commands_accepted": min(4, 1 + i // 120),
                    "source_rejections": 0,
                }, t)  # fmt: skip
            if abs(s - 8.0) < 0.05:
                w.event("info", "BAY_BUILT", "bay 1 built and inspected", t)
            if abs(s - seconds * 0.8) < 0.05:
                w.event("error", "LIFTER_ENCODER", "lifter encoder 3 disagrees with the others by 12 mm", t)
            if abs(s - 35.0) < 0.05:
                w.event("info", "MEMBER_PLACED", "bay2/vertical/x0_y1 placed and riveted", t)
            if progress is not None and i % 100 == 0:
                progress(s)
        w.event("info", "DEMO_END", "end of the demo story", start + seconds)
        # A datagram the GSW refuses (bad CRC), as a noisy link would deliver one.
        zeros = {f.name: 0 for f in defs.packet("link_stats").fields}
        good = encode_telemetry(defs, "link_stats", zeros, seq_count=0, timestamp=start + seconds)
        bad = good[:-1] + bytes([good[-1] ^ 0xFF])
        recorder.record("rx", bad, parse_datagram(bad, defs), recorded_at=start + seconds)
        count = w.count + 1
    return DemoArchive(path, shape, count, start, start + seconds)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("archive", help="new archive file to write")
    parser.add_argument("--tree-definition", help="also write the CRS tree definition JSON here")
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args(argv)
    try:
        demo = write_demo_archive(args.archive, seconds=args.seconds, tree_definition=args.tree_definition)
    except (FileExistsError, OSError) as exc:
        print(f"demo_archive: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {demo.packets} packets to {demo.path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
