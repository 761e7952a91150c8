"""Each device fault of a scenario reaches its emulator at the sim time the scenario says."""

from __future__ import annotations

import socket
import time

import pytest
import yaml
from tlt_sim.emulators import dynamixel_protocol as proto
from tlt_sim.model.scene import Scene
from tlt_sim.twin.faults import FaultSchedule
from tlt_sim.twin.settings import load_settings
from tlt_sim.twin.simulation import Twin

from tlt_drivers.lifter.protocol import StateRequest

SCENARIO = {
    "name": "device_faults_soon",
    "description": "every device fault within a second",
    "faults": {
        "servo_failure": [{"link": "active_grippers", "servo_id": 2, "at_s": 0.3}],
        "limit_switch_stuck": [{"switch": 4, "pressed": True, "at_s": 0.2}],
        "link_drop": [
            {"link": "ur_x", "at_s": 0.4, "duration_s": 0.3},
            {"link": "camera_mounts", "at_s": 0.1, "duration_s": 0.2},
            {"link": "lifter", "at_s": 0.5, "duration_s": 0.2},
        ],
    },
}


def _ping(chain, dxl_id: int) -> bytes:
    return chain.handle(proto.build_packet(dxl_id, proto.PING))


def _connects(host: str, port: int = 30004) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.5):
            return True
    except OSError:
        return False


def _refused_soon(host: str) -> bool:
    """True once connections are refused; a listener in accept() lingers up to its 0.2 s timeout."""
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline:
        if not _connects(host):
            return True
        time.sleep(0.05)
    return False


def test_every_device_fault_appears_at_its_time(make_twin, tmp_path):
    path = tmp_path / "faults.yaml"
    path.write_text(yaml.safe_dump(SCENARIO))
    twin = make_twin(scenario=path)
    twin.start()
    d = twin.devices
    servos, mounts, fw = d.chains["active_grippers"], d.chains["camera_mounts"], d.firmware
    ur_host = twin.settings.ur_hosts["ur_x"]
    assert _ping(servos, 2) and _ping(mounts, 1) and not fw.limit_switches()[4]
    assert fw.receive(StateRequest().encode(1))
    assert _connects(ur_host)

    twin.run_for(0.15)  # camera mounts link down at 0.1 s
    assert not _ping(mounts, 1) and not _ping(mounts, 2)
    twin.run_for(0.1)  # 0.25 s: switch 4 stuck pressed since 0.2 s, though the carriage is at 0.1 m
    assert fw.limit_switches()[4] and twin.scene.position("lifter_joint_0") > 0.05
    twin.run_for(0.1)  # 0.35 s: mounts back (0.3 s), servo 2 dead (0.3 s), the others fine
    assert _ping(mounts, 1)
    assert not _ping(servos, 2) and _ping(servos, 1)
    assert servos.servo(2).get("torque_enable") == 0
    twin.run_for(0.1)  # 0.45 s: the UR link is down
    assert _refused_soon(ur_host)
    twin.run_for(0.1)  # 0.55 s: the lifter firmware hears nothing
    assert fw.receive(StateRequest().encode(2)) == b""
    twin.run_for(0.25)  # 0.8 s: UR (0.7 s) and lifter (0.7 s) back
    assert fw.receive(StateRequest().encode(3))
    assert _connects(ur_host)
    assert [what for _, what in twin.faults.applied] == [
        "camera_mounts link drops",
        "lifter limit switch 4 stuck pressed",
        "active_grippers servo 2 fails",
        "camera_mounts link back",
        "ur_x link drops",
        "lifter link drops",
        "ur_x link back",
    ]
    times = [t for t, _ in twin.faults.applied]
    assert times == sorted(times) and times[0] == pytest.approx(0.1, abs=0.011)


def test_a_servo_failure_on_a_servo_that_is_not_there_is_refused(make_twin):
    twin = make_twin()
    with pytest.raises(ValueError, match="active_grippers has no servo 9"):
        FaultSchedule(
            {"servo_failure": [{"link": "active_grippers", "servo_id": 9, "at_s": 1.0}]}, twin.devices
        )


def test_shipped_device_fault_scenario_schedules_its_faults(tmp_path):
    scene = Scene(scenario="config/twin/scenarios/device_faults.yaml", out_dir=tmp_path / "m")
    settings = load_settings().replace(ur_hosts={"ur_x": "127.0.79.2", "ur_y": "127.0.79.3"})
    with Twin(scene, settings, tmp_path / "run") as twin:
        # Switch 4 is stuck from time 0: it reads pressed as soon as the links are up.
        assert twin.devices.firmware.limit_switches()[4]
        assert twin.faults.pending == [
            (30.0, "active_grippers servo 2 fails"),
            (60.0, "ur_x link drops"),
            (65.0, "ur_x link back"),
        ]
    scene.close()
