"""The CRS node's ground bridge in process, against stand-in ARSs, vision and drivers, with a GSW
link as the ground: the acknowledgements of one command, counted.

A command is validated when it arrives and again when it executes; whatever happens, it is
acknowledged *accepted* at most once, and ends with exactly one *rejected*, *completed* or
*failed* acknowledgement.
"""

from __future__ import annotations

import os
import time

import pytest
import yaml

from tlt_common.ccsds.auth import KeyRing, write_key_file
from tlt_common.ccsds.codec import Packet
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.link_config import load_link_config
from tlt_common.ccsds.reasons import AckStage, Reason
from tlt_crs.ground_bridge import GroundBridge
from tlt_crs.node import build_node
from tlt_gsw.link import GswLink, SentCommand

WAIT = 15.0
# How long a command's acknowledgements are listened to after its final one: none may follow.
QUIET_S = 0.5


@pytest.fixture
def ground(rig, crs, tmp_path):
    """(CRS node with its ground bridge, the GSW's link to it, every packet the GSW received)."""
    node = build_node(crs.fast_config(tmp_path))
    rig.add(node)
    crs.wait_for(lambda: not node.ctx.not_ready(), what="driver states")
    crs.wait_for(
        lambda: node.ctx.board.get("tower_built") is not None, timeout=10.0, what="the blackboard initialised"
    )
    key_file = write_key_file(tmp_path / "keys" / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    link_yaml = tmp_path / "link.yaml"
    link_yaml.write_text(
        yaml.safe_dump(
            {
                "key_file": str(key_file),
                "key_id": 1,
                "crs": {
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "gsw_host": "",
                    "gsw_port": 0,
                    "replay_state": str(tmp_path / "replay.json"),
                },
                "gsw": {
                    "crs_host": "127.0.0.1",
                    "crs_port": 0,
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "archive": str(tmp_path / "archive.sqlite"),
                    "command_state": str(tmp_path / "seq.json"),
                },
            }
        )
    )
    bridge = GroundBridge(node, load_link_config(link_yaml)).start()
    packets: list[Packet] = []
    gsw = GswLink(
        load_definitions(),
        KeyRing.load(key_file),
        1,
        bridge.link.address,
        on_packet=lambda result: packets.append(result) if isinstance(result, Packet) else None,
    )
    yield node, gsw, packets
    gsw.close()
    bridge.close()
    node.interrupt()
    node.destroy_node()


def _stages(gsw: GswLink, sent: SentCommand) -> list[AckStage]:
    """Every acknowledgement of ``sent``: until its final one, then for QUIET_S more."""
    assert gsw.wait_ack(sent, final=True, timeout=WAIT) is not None, f"no final ack of {sent}"
    deadline = time.monotonic() + QUIET_S
    while (left := deadline - time.monotonic()) > 0:
        gsw.poll(left)
    return [ack.stage for ack in sent.acks]


def _start(gsw: GswLink) -> None:
    """Start from the ground, again while refused as not ready (a stand-in's state can arrive late
    enough on a loaded machine to count as silent for a moment)."""
    deadline = time.monotonic() + 10.0
    while True:
        sent = gsw.send_command("start")
        final = gsw.wait_ack(sent, final=True, timeout=WAIT)
        assert final is not None, "no final ack of start"
        if not final.detail.startswith("not ready"):
            assert final.stage is AckStage.COMPLETED, final
            return
        assert time.monotonic() < deadline, final
        time.sleep(0.2)


def test_a_command_is_acknowledged_accepted_once_then_completed(ground):
    node, gsw, packets = ground
    sent = gsw.send_command("set_blackboard_value", {"key": "inspection_attempts", "value": 4})
    assert _stages(gsw, sent) == [AckStage.ACCEPTED, AckStage.COMPLETED]
    assert node.ctx.board.get("inspection_attempts") == 4
    # The CRS's event of it reaches the ground too (the bridge listens to the context's events).
    deadline = time.monotonic() + WAIT
    while not any(p.kind == "event" and p.fields["code"] == "BLACKBOARD_SET" for p in packets):
        assert time.monotonic() < deadline, "no BLACKBOARD_SET event reached the ground"
        gsw.poll(0.2)


def test_a_command_refused_on_arrival_is_rejected_once_and_never_accepted(ground):
    node, gsw, _ = ground
    sent = gsw.send_command("resume")
    assert _stages(gsw, sent) == [AckStage.REJECTED]
    ack = sent.acks[0]
    assert ack.reason is Reason.REFUSED and "not paused" in ack.detail
    assert not node.ctx.paused


def test_a_command_refused_at_execution_fails_once_after_its_one_acceptance(ground):
    """Two Pauses that arrive before the tree runs the first: both pass the arrival check, the
    second fails the execution check (already paused), each acknowledged accepted once."""
    node, gsw, _ = ground
    _start(gsw)
    with node.ctx.lock:  # the tree's tick waits: neither Pause executes before both are accepted
        first, second = gsw.send_command("pause"), gsw.send_command("pause")
        for sent in (first, second):
            ack = gsw.wait_ack(sent, timeout=WAIT)
            assert ack is not None and ack.stage is AckStage.ACCEPTED, ack
    assert _stages(gsw, first) == [AckStage.ACCEPTED, AckStage.COMPLETED]
    assert _stages(gsw, second) == [AckStage.ACCEPTED, AckStage.FAILED]
    failed = second.acks[-1]
    assert failed.reason is Reason.EXECUTION_FAILED and "already paused" in failed.detail
    assert node.ctx.paused


def test_every_agents_tree_definition_reaches_the_ground_and_names_its_status(ground, rig):
    """The CRS sends its own tree's definition and forwards an ARS's (published on the ARS's
    ``tree_definition`` topic): the ground names every node of both statuses with no file."""
    import py_trees
    from py_trees.common import Status

    from tlt_common import ros_names
    from tlt_common.bt.ros import TreeStatusPublisher
    from tlt_common.bt.shape_definition import DefinitionAssembler, DefinitionPart
    from tlt_common.bt.status_codec import Reassembler, StatusPart

    node, gsw, packets = ground
    # The CRS sends telemetry where commands come from: a ground station that starts after the
    # CRS's first definitions went out (lost) learns them from the periodic resend.
    assert gsw.wait_ack(gsw.send_command("resume"), final=True, timeout=WAIT) is not None
    leaves = [py_trees.behaviours.Success("Approach Dispenser"), py_trees.behaviours.Running("Grasp Part")]
    tree = py_trees.trees.BehaviourTree(py_trees.composites.Sequence("ARS x", memory=False, children=leaves))
    publisher = TreeStatusPublisher(
        rig.node,
        "ars_x",
        topic=ros_names.tree_status_topic("ars_x"),
        definition_topic=ros_names.tree_definition_topic("ars_x"),
    )
    publisher.attach(tree)
    assembler = DefinitionAssembler()
    shapes: dict[str, object] = {}
    decoded = {}
    seen = 0
    deadline = time.monotonic() + WAIT
    while not {"crs", "ars_x"} <= decoded.keys():
        assert time.monotonic() < deadline, f"definitions {sorted(shapes)}, decoded {sorted(decoded)}"
        tree.tick()
        gsw.poll(0.2)
        for packet in packets[seen:]:
            if packet.kind == "tree_definition":
                shape = assembler.add(DefinitionPart.from_fields(packet.fields))
                if shape is not None:
                    shapes[packet.fields["agent"]] = shape
            elif packet.kind == "tree_status" and packet.fields["agent"] in shapes:
                f = packet.fields
                part = StatusPart(f["agent"], f["shape_hash"], f["tick"], f["node_count"], f["part_index"],
                                  f["part_count"], f["first_node"], f["status"])  # fmt: skip
                status = Reassembler(shapes[part.agent]).add(part)
                if status is not None:
                    decoded[part.agent] = status
        seen = len(packets)
    assert shapes["crs"].hash == node.shape.hash
    assert decoded["ars_x"].as_dict()["ARS x/Grasp Part"] is Status.RUNNING
    assert [path for path, _ in decoded["crs"].nodes] == [n.path for n in node.shape.nodes]


def test_each_lever_of_table_1_reaches_what_acts_on_it_from_the_ground(ground, rig):
    """Over the authenticated link, from the GSW: a write to an ARS key reaches that ARS, a tower
    correction reaches the CRS's model, an actuator state of the table reaches its driver."""
    node, gsw, packets = ground
    sent = gsw.send_command("set_blackboard_value", {"key": "ars_y/planning_timeout_s", "value": 30.0})
    assert _stages(gsw, sent) == [AckStage.ACCEPTED, AckStage.COMPLETED]
    assert rig.ars["ars_y"].config.raw["timeouts"]["planning_s"] == 30.0
    sent = gsw.send_command("set_blackboard_value", {"key": "tower/bay1/cross_frame", "value": "placed"})
    assert _stages(gsw, sent) == [AckStage.ACCEPTED, AckStage.COMPLETED]
    assert node.ctx.model.state("bay1/cross_frame") == 1  # PLACED
    sent = gsw.send_command("set_actuator_state", {"actuator": "camera_mounts", "state": "inspect_bay"})
    assert _stages(gsw, sent) == [AckStage.ACCEPTED, AckStage.COMPLETED]
    assert rig.cameras.positions == list(node.ctx.config.camera_mounts.inward)
    deadline = time.monotonic() + WAIT
    while not any(p.kind == "event" and p.fields["code"] == "TOWER_CORRECTED" for p in packets):
        assert time.monotonic() < deadline, "no TOWER_CORRECTED event reached the ground"
        gsw.poll(0.2)


@pytest.mark.parametrize(
    ("params", "reason"),
    [
        ({"key": "ars_x/settle_s", "value": -1.0}, "key 'settle_s': -1.0 is below the minimum 0"),
        ({"key": "tower/bay1/vertical/x0_y1", "value": "needs_inspection"}, "only an inspected member"),
        ({"key": "dispenser/cross_frame_dispenser", "value": 40}, "can hold at most 3 part(s)"),
    ],
)
def test_a_lever_the_crs_refuses_is_rejected_with_its_reason_on_the_ground(ground, rig, params, reason):
    node, gsw, _ = ground
    revision = node.ctx.model.revision
    sent = gsw.send_command("set_blackboard_value", params)
    assert _stages(gsw, sent) == [AckStage.REJECTED]
    ack = sent.acks[0]
    assert ack.reason is Reason.REFUSED and reason in ack.detail, ack
    assert node.ctx.model.revision == revision and rig.ars["ars_x"].config.raw["arm"]["settle_s"] == 1.0
