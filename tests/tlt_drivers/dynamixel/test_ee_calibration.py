"""EE width-joint calibration over the real driver and the emulated chain: seek, zero, refuse before."""

from __future__ import annotations

import time

import pytest
from tlt_sim.emulators.dynamixel_chain import DynamixelChain

from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface
from tlt_drivers.dynamixel.config import validate_chain
from tlt_drivers.dynamixel.ee_calibration import CalibrationState, WidthCalibration

LEAD = 0.01
SWITCH_TICKS = 2048 - 0.002 / LEAD * 4096


def make(port: str) -> DynamixelChainInterface:
    joints = [
        {
            "name": "width",
            "id": 3,
            "mode": "extended_position",
            "controller": "group_position",
            "unit": "m",
            "lead_m_per_rev": LEAD,
            "zero_ticks": 0,
            "lower": 0.0,
            "upper": 0.05,
            "max_velocity": 0.008,
        }
    ]
    return DynamixelChainInterface(
        validate_chain(
            {"component": "ee_x", "port": port, "joints": joints, "comm": {"latency_timer_ms": 60.0}}
        )
    )


def settle(chain: DynamixelChain, seen: int) -> None:
    deadline = time.monotonic() + 2.0
    while chain.packets_seen < seen and time.monotonic() < deadline:
        time.sleep(0.001)


SETTINGS = {
    "direction": -1,
    "speed": 0.005,
    "switch_position": 0.0,
    "max_travel": 0.01,
    "timeout_s": 5.0,
    "on_start": False,
}


def run_cycles(chain, hw, cal, seconds, dt=0.02):
    """The node's loop, by hand: read, calibration override, write, then let the emulated servo move."""
    t = 0.0
    while t < seconds and cal.state == CalibrationState.SEEKING:
        assert hw.read(t), hw.fault
        hw.command.update(cal.update(t))
        seen = chain.packets_seen
        assert hw.write(t), hw.fault
        settle(chain, seen + 1)
        chain.advance(dt)
        t += dt
    return t


@pytest.fixture
def rig():
    chain = DynamixelChain([3], clock=None)
    chain.start()
    hw = make(chain.port)
    assert hw.configure() and hw.activate(), hw.fault
    yield chain, hw
    hw.shutdown()
    chain.stop()


def test_seek_zero_and_then_commands_are_in_calibrated_units(rig):
    chain, hw = rig
    cal = WidthCalibration(hw, "width", SETTINGS, lambda: chain.servo(3).position <= SWITCH_TICKS)
    assert "not calibrated" in cal.refusal()
    assert cal.start(0.0) is None
    t = run_cycles(chain, hw, cal, 3.0)
    assert cal.state == CalibrationState.CALIBRATED and cal.refusal() is None
    assert t == pytest.approx(0.002 / 0.005, abs=0.15)  # seeks at the configured speed
    assert hw.position["width"] == pytest.approx(0.0)
    hw.command["width"] = 0.004
    seen = chain.packets_seen
    assert hw.write(0.0)
    settle(chain, seen + 1)
    chain.advance(2.0)
    assert hw.read(0.0)
    assert hw.position["width"] == pytest.approx(0.004, abs=1e-5)


def test_seek_fails_after_max_travel_with_reason(rig):
    chain, hw = rig
    settings = dict(SETTINGS, max_travel=0.001)
    cal = WidthCalibration(hw, "width", settings, lambda: False)
    cal.start(0.0)
    run_cycles(chain, hw, cal, 3.0)
    assert cal.state == CalibrationState.FAILED
    assert "limit switch not reached" in cal.refusal() and "width" not in hw.unclamped


def test_cannot_start_while_hardware_inactive(rig):
    _, hw = rig
    hw.deactivate()
    cal = WidthCalibration(hw, "width", SETTINGS, lambda: False)
    assert "cannot calibrate, hardware is INACTIVE" in cal.start(0.0)


def test_a_calibration_waiting_for_an_operator_moves_nothing_until_one_chooses(rig):
    chain, hw = rig
    cal = WidthCalibration(hw, "width", SETTINGS, lambda: chain.servo(3).position <= SWITCH_TICKS)
    assert "not waiting for an operator" in cal.start_when_released()  # nothing to choose yet
    cal.hold_for_operator("count lost while a part is held")
    assert cal.state == CalibrationState.WAITING and cal.update(0.0) == {}  # no seek commands
    assert "waiting for an operator: count lost while a part is held" in cal.refusal()
    assert cal.start_when_released() is None and cal.when_released
    assert cal.start_when_released() is None  # asked twice, said once
    assert cal.reason.count("once the part is put down") == 1
    assert cal.state == CalibrationState.WAITING and cal.update(0.1) == {}
    assert cal.start(0.0) is None and not cal.when_released  # the driver starts it (or "now")
    run_cycles(chain, hw, cal, 3.0)
    assert cal.state == CalibrationState.CALIBRATED
