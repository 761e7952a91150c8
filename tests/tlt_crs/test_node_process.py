"""The CRS as a real process (``python -m tlt_crs.node``) against stand-ins in this process: a
one-bay build, SIGKILL mid-bay and restart with no member added twice, ROS time, bad input."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from tlt_common import json_lines
from tlt_common.free_port import free_udp_port
from tlt_common.ros.isolation import isolate


def _config(tmp_path, crs, mission=None, **extra):
    data = {
        "mission": str(mission or crs.ONE_BAY),
        "state_file": str(tmp_path / "state" / "tower.json"),
        "writable_blackboard": str(crs.REGISTRY),
        "tick_rate_hz": 50.0,
        "timeouts": {"ars_server_s": 10.0, "service_s": 10.0, "forward_s": 0.5, "sensor_max_age_s": 1.5},
    }
    data.update(extra)
    path = tmp_path / "crs.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


# The processes of these tests get a ROS domain of their own: ROS participants the in-process
# tests of this session leave behind (rclpy does not destroy a participant at shutdown) made the
# CRS process's goals go unanswered when these tests ran after them.
PROCESS_ENV = dict(os.environ)
isolate(PROCESS_ENV)


def _start(config, *args):
    return subprocess.Popen(
        [sys.executable, "-m", "tlt_crs.node", "--config", str(config), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=PROCESS_ENV,
    )


RIG = Path(__file__).with_name("rig_process.py")


class RigProcess:
    """The stand-ins in their own process; ``entries(kind)`` reads what they recorded."""

    def __init__(self, tmp_path, *args):
        self.record = tmp_path / "rig.jsonl"
        self.proc = subprocess.Popen(
            [sys.executable, str(RIG), str(self.record), *args],
            stdout=(tmp_path / "rig.log").open("w"),
            stderr=subprocess.STDOUT,
            env=PROCESS_ENV,
        )
        deadline = time.monotonic() + 30
        while not self.entries("ready"):
            assert time.monotonic() < deadline and self.proc.poll() is None, "rig process did not start"
            time.sleep(0.05)

    def entries(self, kind):
        return json_lines.read(self.record, kind)

    def close(self):
        self.proc.terminate()
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


@pytest.fixture
def rig_process(tmp_path):
    processes = []

    def start(*args):
        processes.append(RigProcess(tmp_path, *args))
        return processes[-1]

    yield start
    for p in processes:
        p.close()


def _states(path):
    try:
        return json.loads(path.read_text())["members"]
    except (OSError, ValueError, KeyError):
        return {}


def _wait(crs, proc, predicate, timeout, what):
    try:
        crs.wait_for(predicate, timeout=timeout, what=what)
    except AssertionError:
        proc.kill()
        out = proc.stdout.read()
        raise AssertionError(f"{what} not reached in {timeout} s; CRS output:\n{out[-4000:]}") from None


def _stop(proc, sig=signal.SIGINT):
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            return proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def test_process_builds_one_bay_and_shuts_down_cleanly(rig_process, crs, tmp_path):
    rig = rig_process()
    config = _config(tmp_path, crs)
    state = tmp_path / "state" / "tower.json"
    proc = _start(config, "--autostart")
    try:
        _wait(
            crs,
            proc,
            lambda: _states(state) and all(v != "NOT_PLACED" for v in _states(state).values()),
            # Autostart first waits until every ARS and vision server is discovered.
            timeout=60.0,
            what="tower built by the CRS process",
        )
        assert set(_states(state).values()) <= {"INSPECTED", "RIVETED"}
        assert len(rig.entries("request")) == 17
    finally:
        code = _stop(proc)
    assert code == 0, proc.stdout.read()


def test_sigkill_mid_bay_and_restart_never_adds_a_placed_member_again(rig_process, crs, tmp_path):
    rig = rig_process("--hold-s", "0.15")
    config = _config(tmp_path, crs)
    state = tmp_path / "state" / "tower.json"
    proc = _start(config, "--autostart")
    try:
        _wait(
            crs,
            proc,
            lambda: sum(v != "NOT_PLACED" for v in _states(state).values()) >= 4,
            timeout=30.0,
            what="four members placed",
        )
    finally:
        proc.kill()  # SIGKILL: no clean-up of any kind
        proc.wait()
    at_kill = _states(state)
    placed = {m for m, s in at_kill.items() if s != "NOT_PLACED"}
    riveted = {m for m, s in at_kill.items() if s in ("RIVETED", "INSPECTED")}
    before = len(rig.entries("request"))
    time.sleep(0.5)  # let the stand-ins finish or drop the orphaned goal
    proc = _start(config, "--autostart")
    try:
        _wait(
            crs,
            proc,
            lambda: all(v in ("RIVETED", "INSPECTED") for v in _states(state).values()),
            timeout=30.0,
            what="tower built after the restart",
        )
    finally:
        _stop(proc)
    after = rig.entries("request")[before:]
    adds = [r["member"] for r in after if r["request"] in ("add_member", "add_cross_frame")]
    affixes = [r["member"] for r in after if r["request"] in ("affix_member", "foundation_rivet")]
    assert adds and not set(adds) & placed, (placed, adds)
    assert not set(affixes) & riveted, (riveted, affixes)
    assert len(adds) == len(set(adds))


def test_ticks_follow_ros_time_when_use_sim_time_is_set(rig_process, crs, tmp_path):
    rig = rig_process("--clock-after", "3.0")
    proc = _start(_config(tmp_path, crs), "--ros-args", "-p", "use_sim_time:=true")
    try:
        _wait(crs, proc, lambda: rig.entries("tree_status"), 30.0, "a tree status on ROS time")
        started = rig.entries("clock_started")
        first = rig.entries("tree_status")[0]
        # Nothing ticked before /clock ran, and the status carries the simulated time.
        assert started and first["wall"] >= started[0]["wall"]
        assert first["sec"] >= 1000
    finally:
        code = _stop(proc, signal.SIGTERM)  # as a launcher stops it
    assert code == 0, proc.stdout.read()


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (lambda m: m.update(bay_count=2), "bay_count"),
        (lambda m: m["bays"][0]["far_verticals"][0].update(affix_ars="ars_x"), "far_verticals[0]"),
        (lambda m: m["dispensers"][0].update(count=-1), "dispensers[0].count"),
    ],
)
def test_malformed_mission_is_refused_with_file_key_and_reason(tmp_path, crs, edit, expected):
    mission = yaml.safe_load(crs.ONE_BAY.read_text())
    edit(mission)
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(mission))
    proc = _start(_config(tmp_path, crs, mission=bad))
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 2
    assert "refused" in out and str(bad) in out and expected in out
    assert not (tmp_path / "state" / "tower.json").exists()  # nothing created


def test_bad_configuration_is_refused(tmp_path, crs):
    config = _config(tmp_path, crs, tick_rate_hz=-1)
    proc = _start(config)
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 2 and "tick_rate_hz" in out and str(config) in out


def test_a_bad_ars_whitelist_is_refused_with_file_key_and_reason(tmp_path, crs):
    """The CRS checks a ground write to an ARS key against the ARSs' whitelist: it loads it at start."""
    bad = tmp_path / "ars_keys.yaml"
    bad.write_text("keys:\n  settle_s: {type: float, writable: true, meaning: m, minimum: 5, maximum: 1}\n")
    proc = _start(_config(tmp_path, crs, ars_writable_blackboard=str(bad)))
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 2 and str(bad) in out and "keys.settle_s" in out and "above maximum" in out


def test_state_file_of_another_mission_is_refused(tmp_path, crs):
    from tlt_common.mission.schema import load_mission
    from tlt_common.mission.tower_model import TowerModel

    state = tmp_path / "state" / "tower.json"
    state.parent.mkdir()
    TowerModel(load_mission(crs.TWO_BAY), state)
    before = state.read_bytes()
    proc = _start(_config(tmp_path, crs))
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 2 and "belongs to mission 'two_bay'" in out
    assert state.read_bytes() == before


def test_processes_run_in_a_domain_of_their_own():
    assert PROCESS_ENV["ROS_DOMAIN_ID"] != os.environ["ROS_DOMAIN_ID"]


def _ars_tree_status_reaches_the_ground(gsw, packets) -> None:
    """An ARS's TreeStatus, published in the CRS processes' domain, is forwarded as tree_status."""
    import rclpy
    from rclpy.node import Node
    from tlt_interfaces.msg import TreeStatus

    from tlt_common import ros_names

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(PROCESS_ENV["ROS_DOMAIN_ID"]))
    node = Node("ars_x_stand_in", context=context)
    pub = node.create_publisher(TreeStatus, ros_names.tree_status_topic("ars_x"), 10)
    sent = TreeStatus(
        agent="ars_x",
        shape_hash=0xC0FFEE,
        tick_count=7,
        node_count=5,
        part_index=0,
        part_count=1,
        first_node=0,
        status=[0b01101100, 0b11000000],
    )
    try:
        deadline = time.monotonic() + 15
        while not any(p.kind == "tree_status" and p.fields["agent"] == "ars_x" for p in packets):
            assert time.monotonic() < deadline, "the ARS tree status never reached the ground"
            pub.publish(sent)
            gsw.poll(0.2)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
    got = next(p for p in packets if p.kind == "tree_status" and p.fields["agent"] == "ars_x").fields
    assert (got["shape_hash"], got["tick"], got["node_count"]) == (0xC0FFEE, 7, 5)
    assert bytes(got["status"]) == bytes([0b01101100, 0b11000000])


def test_ground_commands_over_ccsds_reach_the_tree(rig_process, crs, tmp_path):
    """End to end from the ground: authenticated Start, Pause, Set Blackboard Value, Resume and
    Stop over CCSDS/UDP act on the CRS process's tree; bad commands are refused and never act."""
    from tlt_common.ccsds.auth import KeyRing, write_key_file
    from tlt_common.ccsds.codec import Packet
    from tlt_common.ccsds.definitions import load_definitions
    from tlt_common.ccsds.reasons import AckStage, Reason
    from tlt_gsw.link import GswLink

    rig_process("--hold-s", "3.0")  # each ARS request takes a while: the build is mid-way throughout
    key_file = write_key_file(tmp_path / "keys" / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    port = free_udp_port()
    link_yaml = tmp_path / "link.yaml"
    link_yaml.write_text(
        yaml.safe_dump(
            {
                "key_file": str(key_file),
                "key_id": 1,
                "crs": {
                    "bind_host": "127.0.0.1",
                    "bind_port": port,
                    "gsw_host": "",
                    "gsw_port": 0,
                    "replay_state": str(tmp_path / "replay.json"),
                },
                "gsw": {
                    "crs_host": "127.0.0.1",
                    "crs_port": port,
                    "bind_host": "127.0.0.1",
                    "bind_port": 0,
                    "archive": str(tmp_path / "archive.sqlite"),
                    "command_state": str(tmp_path / "seq.json"),
                },
            }
        )
    )
    proc = _start(_config(tmp_path, crs), "--ground-link", str(link_yaml))
    packets: list[Packet] = []
    gsw = GswLink(
        load_definitions(),
        KeyRing.load(key_file),
        1,
        ("127.0.0.1", port),
        on_packet=lambda result: packets.append(result) if isinstance(result, Packet) else None,
    )

    def command(name, params=None, timeout=15.0):
        sent = gsw.send_command(name, params)
        ack = gsw.wait_ack(sent, final=True, timeout=timeout)
        assert ack is not None, f"no final acknowledgement of {name}"
        return ack

    def mission(predicate, what, timeout=20.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            gsw.poll(0.2)
            for packet in reversed(packets):
                if packet.kind == "hk_mission":
                    if predicate(packet.fields):
                        return packet.fields
                    break
        last = next((p.fields for p in reversed(packets) if p.kind == "hk_mission"), None)
        raise AssertionError(f"{what}: not seen in hk_mission telemetry (last: {last})")

    try:
        # The CRS process takes a moment to bind (until then a Start goes unheard) and to hear
        # from its drivers (until then Start is refused: not ready).
        deadline = time.monotonic() + 60
        while True:
            sent = gsw.send_command("start")
            ack = gsw.wait_ack(sent, final=True, timeout=2.0)
            if ack is not None and not ack.detail.startswith("not ready"):
                break
            if ack is not None:
                time.sleep(0.5)
            assert time.monotonic() < deadline and proc.poll() is None, "the CRS never answered Start"
        assert ack.stage is AckStage.COMPLETED, ack
        mission(lambda f: f["started"] and f["run_state"] == "running", "started and running")

        assert command("pause").stage is AckStage.COMPLETED
        mission(lambda f: f["run_state"] == "paused", "paused")
        refused = command("pause")
        assert (refused.stage, refused.reason) == (AckStage.REJECTED, Reason.REFUSED)
        assert "already paused" in refused.detail

        assert (
            command("set_blackboard_value", {"key": "inspection_attempts", "value": 4}).stage
            is AckStage.COMPLETED
        )
        out_of_range = command("set_blackboard_value", {"key": "inspection_attempts", "value": 9})
        assert out_of_range.stage is AckStage.REJECTED and "inspection_attempts" in out_of_range.detail
        read_only = command("set_blackboard_value", {"key": "tower_built", "value": True})
        assert read_only.stage is AckStage.REJECTED
        gsw.send_raw(b"\x18\x10\xc0\x00\x00\x05not a command")  # no ack, no action, the CRS goes on
        deadline = time.monotonic() + 10
        while not any(p.kind == "event" and p.fields["code"] == "BLACKBOARD_SET" for p in packets):
            assert time.monotonic() < deadline, "no BLACKBOARD_SET event reached the ground"
            gsw.poll(0.2)
        (event,) = [p for p in packets if p.kind == "event" and p.fields["code"] == "BLACKBOARD_SET"]
        assert event.fields["text"] == "inspection_attempts = 4"

        assert command("resume").stage is AckStage.COMPLETED
        mission(lambda f: f["run_state"] == "running", "running again")
        deadline = time.monotonic() + 10
        while not any(p.kind == "tree_status" and p.fields["agent"] == "crs" for p in packets):
            assert time.monotonic() < deadline, "no CRS tree_status reached the ground"
            gsw.poll(0.2)
        _ars_tree_status_reaches_the_ground(gsw, packets)
        tower = next(p for p in reversed(packets) if p.kind == "hk_tower")
        assert tower.fields["member_count"] == 13 and len(tower.fields["member_states"]) == 4
        lifter = next(p for p in reversed(packets) if p.kind == "hk_lifter")
        assert lifter.fields["link_ok"] is True

        assert command("stop").stage is AckStage.COMPLETED
        assert proc.wait(timeout=20) == 0
    finally:
        gsw.close()
        _stop(proc)
