"""Scenario device faults as the real drivers' hardware interfaces see them through the twin's links:
a dead servo, a dropped link that comes back, a lifter limit switch stuck pressed."""

from __future__ import annotations

import time

import yaml

from tlt_drivers.dynamixel.config import load_chain
from tlt_drivers.gpio.config import CONFIG_DIR
from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.lifter.config import load_lifter_config
from tlt_drivers.lifter.serial_interface import LifterSerialInterface

SCENARIO = {
    "name": "faults_for_drivers",
    "description": "a servo dies, a link drops for a while, a switch sticks",
    "faults": {
        "servo_failure": [{"link": "active_grippers", "servo_id": 2, "at_s": 0.2}],
        "limit_switch_stuck": [{"switch": 6, "pressed": True, "at_s": 0.1}],
        "link_drop": [{"link": "camera_mounts", "at_s": 0.1, "duration_s": 0.2}],
    },
}


def _chain(twin, component: str):
    from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface

    config = load_chain(CONFIG_DIR / f"{component}.yaml")
    config["port"] = str(twin.run_dir / component)
    # The twin's allowance (config/launch/twin.yaml): on a loaded machine the twin's thread answers
    # past the USB adapter's 16 ms, and a late status packet is not the fault under test.
    config["comm"]["latency_timer_ms"] = 60.0
    hw = DynamixelChainInterface(config)
    assert hw.configure() and hw.activate(), hw.fault
    return hw


def test_drivers_see_each_fault_at_its_time(make_twin, tmp_path):
    path = tmp_path / "faults.yaml"
    path.write_text(yaml.safe_dump(SCENARIO))
    twin = make_twin(scenario=path)
    twin.start()
    grippers, mounts = _chain(twin, "active_grippers"), _chain(twin, "camera_mounts")
    lifter = LifterSerialInterface(
        load_lifter_config(CONFIG_DIR / "lifter.yaml").with_port(str(twin.run_dir / "lifter"))
    )
    assert lifter.configure() and lifter.activate(), lifter.fault
    try:
        assert grippers.read(time.monotonic()) and mounts.read(time.monotonic())
        assert not lifter.telemetry.limit_switches[6]

        twin.run_for(0.15)  # camera mounts' link is down, switch 6 stuck
        assert not mounts.read(time.monotonic()) and mounts.state == Lifecycle.ERROR
        lifter.poll()
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and not lifter.telemetry.limit_switches[6]:
            lifter.read(time.monotonic())
            time.sleep(0.01)
        assert lifter.telemetry.limit_switches[6], "the stuck switch reaches the driver"
        assert grippers.read(time.monotonic())

        twin.run_for(0.1)  # 0.25 s: servo 2 is dead
        assert not grippers.read(time.monotonic())
        assert "active_gripper_2" in grippers.fault

        twin.run_for(0.1)  # 0.35 s: the mounts' link is back and the driver recovers
        assert mounts.recover(), mounts.fault
        assert mounts.read(time.monotonic())
        assert not grippers.recover(), "a dead servo stays dead"
    finally:
        for hw in (grippers, mounts, lifter):
            hw.shutdown()
