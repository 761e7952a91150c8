"""ArchiveModel: the GUI's displays as queries on the archive (no Qt here)."""

from __future__ import annotations

import os

import pytest
from py_trees.common import Status

from tlt_common.bt.shape_definition import split_definition
from tlt_common.bt.status_codec import TreeShape, encode
from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import crc16_ccitt_false, encode_command, encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.sequence import SequenceCounters
from tlt_gsw.archive.query import open_archive
from tlt_gsw.archive.recorder import Recorder
from tlt_gsw.gui.agent_trees import status_counts
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.demo_archive import demo_tree, set_demo_statuses
from tlt_gsw.gui.tree_definitions import TreeDefinitionFiles, load_tree_definition, write_tree_definition

DEFS = load_definitions()
LIFTER = {
    "state": "crs_control", "position_0": 0.5, "position_1": 0.5, "position_2": 0.5, "position_3": 0.5,
    "velocity": 10, "limit_switches": 0, "watchdog_tripped": False, "link_ok": True,
}  # fmt: skip


class ArchiveWriter:
    """Writes real packets into an archive the way the link thread does (parse, then record)."""

    def __init__(self, path, t0: float = 1_800_000_000.0) -> None:
        self.recorder = Recorder(path, batch_size=10_000, flush_interval_s=3600)
        self.counters = SequenceCounters()
        self.t = t0
        self.keyring = KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})
        self.seq = 1000

    def tm(self, kind: str, values: dict, *, seq_count: int | None = None, dt: float = 0.01) -> bytes:
        self.t += dt
        count = self.counters.next(DEFS.packet(kind).apid) if seq_count is None else seq_count
        raw = encode_telemetry(DEFS, kind, values, seq_count=count, timestamp=self.t)
        self.recorder.record("rx", raw, parse_datagram(raw, DEFS), recorded_at=self.t)
        return raw

    def tc(self, name: str, params: dict | None = None) -> int:
        self.t += 0.01
        self.seq += 1
        raw = encode_command(
            DEFS, name, params or {}, key_id=1, key=self.keyring.get(1), security_seq=self.seq,
            seq_count=self.counters.next(DEFS.command_apid), timestamp=self.t,
        )  # fmt: skip
        self.recorder.record("tx", raw, parse_datagram(raw, DEFS, expect="tc", keyring=self.keyring), self.t)
        return self.seq

    def ack(self, name: str, seq: int, stage: str, reason: str = "none", detail: str = "") -> None:
        self.tm("ack", {
            "command_apid": DEFS.command_apid, "command_seq_count": 0, "security_seq": seq,
            "command": name, "stage": stage, "reason": reason, "detail": detail,
        })  # fmt: skip

    def flush(self) -> None:
        self.recorder.flush()

    def close(self) -> None:
        self.recorder.close()


@pytest.fixture
def writer(tmp_path):
    w = ArchiveWriter(tmp_path / "a.sqlite")
    yield w
    w.close()


def model_of(path, **options) -> ArchiveModel:
    return ArchiveModel(open_archive(path), DEFS, **options)


def test_demo_archive_state_after_one_advance(demo):
    archive, definition = demo
    model = model_of(archive.path, shapes={"crs": load_tree_definition(definition)},
                     plot_fields=[("hk_lifter", "position_3"), ("hk_ee", "width")])  # fmt: skip
    changes = model.advance()
    assert changes.packets == archive.packets == model.position
    # Commands: each tx packet matched with its acks by security sequence number.
    stages = {r.name: [a.stage for a in r.acks] for r in model.commands.values()}
    assert stages == {
        "start": ["accepted", "completed"], "pause": ["accepted", "completed"],
        "resume": ["accepted", "completed"], "set_blackboard_value": ["rejected"],
        "set_actuator_state": ["accepted", "completed"],
    }  # fmt: skip
    refused = next(r for r in model.commands.values() if r.name == "set_blackboard_value")
    assert refused.params == {"key": "lifter_speed", "value": 0.5}
    assert refused.acks[0].reason == "bad_parameter_range" and "maximum" in refused.acks[0].detail
    # Housekeeping: newest packet per kind, per agent for per-agent kinds, typed by the definitions.
    lifter = model.housekeeping[("hk_lifter", "")].fields
    assert lifter["link_ok"] is True and lifter["state"] == "crs_control"
    assert DEFS.packet("hk_lifter").fields[4].limits.classify(lifter["position_3"]) == "red"
    assert {i for (k, i) in model.housekeeping if k == "hk_ee"} == {"ars_x", "ars_y"}
    # Events: the CRS's and the datagram the GSW rejected (bad CRC).
    codes = [e.code for e in model.events]
    assert codes[-1] == "DATAGRAM_REJECTED" and model.events[-1].reason == "bad_crc"
    assert {"BAY_BUILT", "COMMAND_REJECTED", "LIFTER_ENCODER"} <= set(codes)
    figures = model.link_figures()
    assert (figures.packets_tx, figures.crc_errors, figures.rejections, figures.gaps) == (5, 1, 1, 0)
    assert figures.packets_rx == archive.packets - 5
    # Tree: decoded against the definition; equal to what the demo tree had at that tick.
    state = model.trees["crs"]
    assert state.error is None and state.decoded is not None
    shape = TreeShape.of(demo_tree())
    set_demo_statuses(shape, state.tick)
    assert [s for _, s in state.decoded.nodes] == shape.statuses()
    assert status_counts(state)[Status.FAILURE] == 2
    # Series: one curve per agent for a per-agent field, 40 s at 2 Hz.
    assert set(model.series[("hk_ee", "width")]) == {"ars_x", "ars_y"}
    assert len(model.series[("hk_lifter", "position_3")][""]) == 81


def test_seek_rebuilds_the_same_state_as_advancing(demo):
    archive, definition = demo
    shapes = {"crs": load_tree_definition(definition)}
    middle = archive.packets // 2
    fresh = model_of(archive.path, shapes=shapes, plot_fields=[("hk_lifter", "velocity")])
    fresh.advance(until=middle)
    scrubbed = model_of(archive.path, shapes=shapes, plot_fields=[("hk_lifter", "velocity")])
    scrubbed.advance()
    changes = scrubbed.seek(middle)
    assert changes.reset and scrubbed.position == middle
    assert scrubbed.housekeeping == fresh.housekeeping
    assert [(r.name, r.acks) for r in scrubbed.commands.values()] == [
        (r.name, r.acks) for r in fresh.commands.values()
    ]
    assert list(scrubbed.events) == list(fresh.events)
    assert list(scrubbed.packets) == list(fresh.packets)
    assert scrubbed.trees["crs"].decoded == fresh.trees["crs"].decoded
    assert scrubbed.link_figures().__dict__ == fresh.link_figures().__dict__
    assert list(scrubbed.series[("hk_lifter", "velocity")][""]) == list(
        fresh.series[("hk_lifter", "velocity")][""]
    )
    # The set_actuator_state command (sent after the middle) is not known yet at the middle.
    assert "set_actuator_state" not in {r.name for r in scrubbed.commands.values()}
    assert scrubbed.seek(0).reset and scrubbed.position == 0 and not scrubbed.housekeeping


def test_advance_reads_at_most_max_rows_per_refresh(demo):
    archive, _ = demo
    model = model_of(archive.path, max_rows_per_refresh=100)
    assert model.advance().packets == 100 and model.position == 100
    model.advance(until=150)
    assert model.position == 150
    while model.advance():
        pass
    assert model.position == archive.packets


def test_gaps_duplicates_and_rejections_are_counted(writer, tmp_path):
    for count in (0, 1, 2, 6, 7, 7):  # 3, 4, 5 lost; one duplicate
        writer.tm("hk_lifter", LIFTER, seq_count=count)
    good = writer.tm("hk_lifter", LIFTER, seq_count=8)
    bad = good[:-2] + bytes([good[-2] ^ 1, good[-1]])
    writer.recorder.record("rx", bad, parse_datagram(bad, DEFS), recorded_at=writer.t)
    writer.flush()
    model = model_of(writer.recorder.path)
    model.advance()
    figures = model.link_figures()
    assert (figures.gaps, figures.missing, figures.crc_errors, figures.rejections) == (1, 3, 1, 1)
    assert figures.by_reason == {"bad_crc": 1}
    assert model.events[-1].source == "gsw" and model.events[-1].reason == "bad_crc"


def test_tree_without_definition_or_of_another_shape_says_why(writer):
    shape = TreeShape.of(demo_tree())
    set_demo_statuses(shape, 1)
    for part in encode(shape, agent="ars_x", tick_count=7, max_status_bytes=4):
        writer.tm("tree_status", {
            "agent": part.agent, "shape_hash": part.shape_hash, "tick": part.tick_count,
            "node_count": part.node_count, "part_index": part.part_index, "part_count": part.part_count,
            "first_node": part.first_node, "status": part.status,
        })  # fmt: skip
    writer.flush()
    unknown = model_of(writer.recorder.path)
    unknown.advance()
    state = unknown.trees["ars_x"]
    assert state.decoded is None and "no tree definition for agent 'ars_x'" in state.error
    assert sum(state.counts.values()) == len(shape)  # the counts are still shown
    other = TreeShape.of(demo_tree().children[0])
    wrong = model_of(writer.recorder.path, shapes={"ars_x": other})
    wrong.advance()
    assert wrong.trees["ars_x"].decoded is None and "shape" in wrong.trees["ars_x"].error


def _send_definition(writer: ArchiveWriter, shape: TreeShape, agent: str, chunk: int = 64) -> None:
    for part in split_definition(shape, agent, max_chunk_bytes=chunk):
        writer.tm("tree_definition", part.fields())


def test_every_agents_tree_is_decoded_from_the_definitions_it_sent_with_no_configuration(writer):
    """Live (advance) and in replay (seek), each agent's status is named with the definition it
    sent over the link; a status that comes before its definition is named once it arrives."""
    crs, ars = TreeShape.of(demo_tree()), TreeShape.of(demo_tree().children[4])
    set_demo_statuses(crs, 3)
    _send_definition(writer, crs, "crs")
    for part in encode(crs, agent="crs", tick_count=3, max_status_bytes=4):
        writer.tm("tree_status", {
            "agent": part.agent, "shape_hash": part.shape_hash, "tick": part.tick_count,
            "node_count": part.node_count, "part_index": part.part_index, "part_count": part.part_count,
            "first_node": part.first_node, "status": part.status,
        })  # fmt: skip
    _send_tree(writer, ars, 1)  # the ARS's definition is not there yet
    writer.flush()
    live = model_of(writer.recorder.path)
    before_ars_definition = live.head()
    assert live.advance().trees == {"crs", "ars_x"}
    assert [s for _, s in live.trees["crs"].decoded.nodes] == crs.statuses()
    assert live.trees["ars_x"].decoded is None and "received yet" in live.trees["ars_x"].error
    _send_definition(writer, ars, "ars_x")
    _send_tree(writer, ars, 2)
    writer.flush()
    live.advance()
    decoded = live.trees["ars_x"].decoded
    assert decoded is not None and [path for path, _ in decoded.nodes] == [n.path for n in ars.nodes]
    # Replay from the first status: the definitions are found in the archive, wherever they lie.
    replay = model_of(writer.recorder.path)
    replay.seek(before_ars_definition)
    assert replay.trees["crs"].decoded is not None and replay.trees["ars_x"].decoded is not None
    assert replay.trees["ars_x"].tick == 1


def test_a_forged_or_partial_definition_names_nothing(writer):
    """Definition parts whose body hashes to another shape, or that never complete, leave the
    status undecoded with the reason; the agent's true definition, once sent, decodes it."""
    shape, other = TreeShape.of(demo_tree()), TreeShape.of(demo_tree().children[4])
    for part in split_definition(other, "ars_x", max_chunk_bytes=64):
        writer.tm("tree_definition", part.fields() | {"shape_hash": shape.hash, "node_count": len(shape)})
    writer.tm("tree_definition", split_definition(shape, "ars_x", max_chunk_bytes=64)[0].fields())
    _send_tree(writer, shape, 1)
    writer.flush()
    model = model_of(writer.recorder.path)
    model.advance()
    assert model.trees["ars_x"].decoded is None and "received yet" in model.trees["ars_x"].error
    _send_definition(writer, shape, "ars_x")
    _send_tree(writer, shape, 2)
    writer.flush()
    model.advance()
    assert model.trees["ars_x"].decoded is not None


def test_a_limit_crossed_between_two_refreshes_is_an_event_and_its_alarm_survives_a_seek(writer):
    """Every packet is checked, not only the newest one shown: a red value followed by a nominal
    one in the same refresh still raises (and clears) an alarm; a replay seek rebuilds the same
    alarms and keeps the operator's acknowledgements."""
    writer.tm("hk_lifter", LIFTER)
    writer.tm("hk_lifter", LIFTER | {"position_1": 2.2})  # red
    writer.tm("hk_lifter", LIFTER)  # back, before any refresh
    writer.tm("hk_arm_joints", {"ars": "ars_y", **{f"q{i}": 0.0 for i in range(6)}, "protective_stop": True})
    writer.flush()
    model = model_of(writer.recorder.path)
    changes = model.advance()
    assert changes.alarms
    codes = [(e.code, e.text) for e in model.events]
    assert codes == [
        ("LIMIT_RED", "hk_lifter.position_1 = 2.2 m: outside its red limits [-0.01, 2]"),
        ("LIMIT_OK", "hk_lifter.position_1 = 0.5 m: back within limits [-0.01, 2]"),
        ("LIMIT_RED", "hk_arm_joints.protective_stop (ars_y) = 1: outside its red limits [0, 0]"),
    ]
    lifter, arm = model.alarms.shown()
    assert not lifter.active and arm.active and arm.raised.instance == "ars_y"
    model.alarms.acknowledge(lifter)
    assert model.alarms.shown() == [arm]
    model.seek(model.head())
    assert [a.id for a in model.alarms.shown()] == [arm.id], "the acknowledgement is kept"
    model.seek(2)  # before the lifter came back: its alarm is active again, and acknowledged
    (alarm,) = model.alarms.shown()
    assert alarm.active and alarm.acknowledged and alarm.raised.field == "position_1"


def test_ack_of_a_command_not_in_the_archive_is_still_shown(writer):
    writer.ack("stop", 424242, "rejected", "bad_auth", "MAC does not verify")
    seq = writer.tc("start")
    writer.ack("start", seq, "accepted")
    writer.flush()
    model = model_of(writer.recorder.path)
    model.advance()
    foreign = model.commands[424242]
    assert foreign.sent_at is None and foreign.name == "stop" and foreign.last_stage == "rejected"
    assert model.commands[seq].sent_at is not None and model.commands[seq].last_stage == "accepted"


def _vm_steps(model: ArchiveModel) -> int:
    steps = [0]

    def count() -> int:
        steps[0] += 1
        return 0

    model.conn.set_progress_handler(count, 50)
    model.advance()
    model.conn.set_progress_handler(None, 0)
    return steps[0]


def test_refresh_cost_follows_new_packets_not_archive_size(tmp_path):
    """The same 200 new packets cost about the same SQLite work on a 400- and a 20,400-packet archive."""
    costs = []
    for name, history in (("small", 400), ("large", 20_400)):
        w = ArchiveWriter(tmp_path / f"{name}.sqlite")
        for i in range(history):
            w.tm("hk_lifter" if i % 2 else "hk_grippers", LIFTER if i % 2 else {
                "top_engaged": 1, "top_position_mean": 0.01, "top_fault": False,
                "active_engaged": 0, "active_height": 0.1, "active_fault": False,
            })  # fmt: skip
        w.flush()
        model = model_of(w.recorder.path, plot_fields=[("hk_lifter", "position_0")])
        while model.advance():
            pass
        for _ in range(200):
            w.tm("hk_lifter", LIFTER)
        w.ack("start", w.tc("start"), "accepted")
        w.flush()
        costs.append(_vm_steps(model))
        w.close()
    small, large = costs
    assert large < 1.5 * small, costs


def _send_tree(writer: ArchiveWriter, shape: TreeShape, tick: int) -> None:
    for part in encode(shape, agent="ars_x", tick_count=tick):
        writer.tm("tree_status", {
            "agent": part.agent, "shape_hash": part.shape_hash, "tick": part.tick_count,
            "node_count": part.node_count, "part_index": part.part_index, "part_count": part.part_count,
            "first_node": part.first_node, "status": part.status,
        })  # fmt: skip
    writer.flush()


def test_an_agent_that_rebuilds_its_tree_is_decoded_with_its_new_definition(writer, tmp_path):
    first, second = TreeShape.of(demo_tree()), TreeShape.of(demo_tree().children[4])
    path = write_tree_definition(first, tmp_path / "ars_x.json")
    files = TreeDefinitionFiles({"ars_x": path})
    model = model_of(writer.recorder.path, shapes=files.load_present(), definition_files=files)
    _send_tree(writer, first, 1)
    model.advance()
    assert model.trees["ars_x"].decoded is not None and len(model.trees["ars_x"].decoded.nodes) == len(first)
    _send_tree(writer, second, 2)  # new shape, definition not written yet
    model.advance()
    assert model.trees["ars_x"].decoded is None and "shape" in model.trees["ars_x"].error
    write_tree_definition(second, path)
    _send_tree(writer, second, 3)
    model.advance()
    state = model.trees["ars_x"]
    assert state.error is None and [p for p, _ in state.decoded.nodes] == [n.path for n in second.nodes]


def test_telemetry_that_fails_authentication_is_counted_apart(writer):
    from tlt_common.ccsds.tm_security import TelemetrySigner, TelemetryVerifier

    signer = TelemetrySigner(writer.keyring.telemetry, 1)
    verifier = TelemetryVerifier(writer.keyring.telemetry)
    genuine = signer.encode(DEFS, "hk_lifter", LIFTER, seq_count=0, timestamp=writer.t)
    altered = bytearray(signer.encode(DEFS, "hk_lifter", LIFTER, seq_count=1, timestamp=writer.t))
    altered[20] ^= 1
    altered[-2:] = crc16_ccitt_false(bytes(altered[:-2])).to_bytes(2, "big")
    for raw in (genuine, genuine, bytes(altered)):  # good, replayed, altered with its CRC recomputed
        result = parse_datagram(raw, DEFS, keyring=verifier, replay=verifier)
        writer.recorder.record("rx", raw, result, recorded_at=writer.t)
    writer.flush()
    model = model_of(writer.recorder.path)
    model.advance()
    figures = model.link_figures()
    assert (figures.packets_rx, figures.rejections, figures.auth_rejections) == (3, 2, 2)
    assert figures.by_reason == {"replay": 1, "bad_auth": 1}


def test_a_replayed_commands_rejection_does_not_change_its_outcome(writer):
    seq = writer.tc("start")
    writer.ack("start", seq, "accepted")
    writer.ack("start", seq, "completed")
    for _ in range(3):  # the CRS rejects copies of it that someone replayed
        writer.ack("start", seq, "rejected", "replay", "sequence is not above the last accepted")
    writer.flush()
    model = model_of(writer.recorder.path)
    model.advance()
    record = model.commands[seq]
    assert (record.last_stage, [a.stage for a in record.acks]) == ("completed", ["accepted", "completed"])
    assert record.replays_rejected == 3
