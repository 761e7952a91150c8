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

from tlt_common.ros_isolation import isolate


def _config(tmp_path, crs, mission=None, **extra):
    data = {
        "mission": str(mission or crs.ONE_BAY),
        "state_file": str(tmp_path / "state" / "tower.json"),
        "writable_blackboard": str(crs.REGISTRY),
        "tick_rate_hz": 50.0,
        "timeouts": {"ars_server_s": 10.0, "service_s": 10.0, "forward_s": 0.5, "sensor_max_age_s": 0.5},
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
        try:
            lines = self.record.read_text().splitlines()
        except OSError:
            return []
        out = []
        for line in lines:
            try:
                entry = json.loads(line)
            except ValueError:
                continue  # a line being written
            if entry["kind"] == kind:
                out.append(entry)
        return out

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


def _stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
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
            timeout=30.0,
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
        _stop(proc)


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
