"""The real dynamixel-sdk driver against the emulated MX-106(2.0) chain over a pseudo-terminal."""

from __future__ import annotations

import math
import time

import pytest
from tlt_sim.emulators.dynamixel_chain import DynamixelChain
from tlt_sim.emulators.dynamixel_servo import HW_ELECTRICAL_SHOCK, HW_OVERLOAD, DynamixelServo

from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface
from tlt_drivers.dynamixel.config import validate_chain
from tlt_drivers.hardware_interface import Lifecycle


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def settle(chain: DynamixelChain, seen: int) -> None:
    """Wait until the emulator thread has handled the packets sent so far (sync writes get no reply)."""
    deadline = time.monotonic() + 2.0
    while chain.packets_seen < seen and time.monotonic() < deadline:
        time.sleep(0.001)


def chain_config(port: str, **extra) -> dict:
    joints = [
        {
            "name": f"grip_{i}",
            "id": i,
            "mode": "position",
            "controller": "trajectory",
            "unit": "rad",
            "lower": -1.5,
            "upper": 1.5,
            "max_velocity": 2.0,
        }
        for i in (1, 2, 3)
    ]
    joints.append(
        {
            "name": "width",
            "id": 4,
            "mode": "extended_position",
            "controller": "group_position",
            "unit": "m",
            "lead_m_per_rev": 0.002,
            "zero_ticks": 0,
            "lower": -0.01,
            "upper": 0.2,
            "max_velocity": 0.05,
        }
    )
    # The emulator shares this process and a busy 2-core host: allow 60 ms of latency, not the USB 16.
    comm = {"latency_timer_ms": 60.0, **extra.pop("comm", {})}
    return validate_chain({"component": "test_chain", "port": port, "joints": joints, "comm": comm, **extra})


@pytest.fixture
def emulated():
    clock = FakeClock()
    chain = DynamixelChain([1, 2, 3, 4], clock=clock)
    chain.start()
    hw = DynamixelChainInterface(chain_config(chain.port))
    yield chain, hw, clock
    hw.shutdown()
    chain.stop()


def test_configure_activate_sets_mode_per_servo_and_torque(emulated):
    chain, hw, _ = emulated
    assert hw.configure(), hw.fault
    assert hw.activate(), hw.fault
    assert [chain.servo(i).get("operating_mode") for i in (1, 2, 3, 4)] == [3, 3, 3, 4]
    assert all(chain.servo(i).get("torque_enable") == 1 for i in (1, 2, 3, 4))
    # The profile velocity follows max_velocity (2 rad/s on a 1:1 joint is 19.1 rpm -> 84 units).
    assert chain.servo(1).get("profile_velocity") == math.ceil(2.0 * 60 / (2 * math.pi) / 0.229)


def test_sync_write_moves_and_sync_read_reports_in_joint_units(emulated):
    chain, hw, _ = emulated
    hw.configure()
    hw.activate()
    hw.command["grip_2"] = 0.5
    hw.command["width"] = 0.01  # 5 lead-screw turns
    seen = chain.packets_seen
    assert hw.write(0.0)
    settle(chain, seen + 1)
    chain.advance(10.0)  # the width servo is held to its 48 rpm velocity limit: 0.01 m takes 6.3 s
    assert hw.read(10.0), hw.fault
    assert hw.position["grip_2"] == pytest.approx(0.5, abs=2 * math.pi / 4096)
    assert hw.position["width"] == pytest.approx(0.01, abs=1e-6)
    assert chain.servo(4).get("present_position") == 5 * 4096
    assert hw.position["grip_1"] == pytest.approx(0.0)


def test_activation_changes_mode_even_if_torque_was_left_on(emulated):
    chain, hw, _ = emulated
    chain.servo(4).write(64, bytes([1]))  # a previous session left torque on in position mode
    assert hw.configure() and hw.activate(), hw.fault
    assert chain.servo(4).get("operating_mode") == 4


def test_wrong_model_refused_naming_the_servo():
    chain = DynamixelChain(
        [DynamixelServo(1), DynamixelServo(2), DynamixelServo(3), DynamixelServo(4)], clock=None
    )
    chain.servo(3).table[0:2] = (1020).to_bytes(2, "little")
    with chain:
        hw = DynamixelChainInterface(chain_config(chain.port))
        assert not hw.configure()
        assert "'grip_3' (id 3) is model 1020, expected 321" in hw.fault
        hw.shutdown()


def test_missing_port_is_a_clear_configure_error(tmp_path):
    hw = DynamixelChainInterface(chain_config(str(tmp_path / "ttyUSB9")))
    assert not hw.configure()
    assert hw.state == Lifecycle.ERROR and "cannot open" in hw.fault


def test_hardware_error_is_read_and_reported_then_reboot_recovers():
    chain = DynamixelChain([1, 2, 3, 4])  # real clock: a rebooting servo is deaf for 50 ms
    with chain:
        hw = DynamixelChainInterface(chain_config(chain.port))
        assert hw.configure() and hw.activate()
        chain.servo(2).inject_hardware_error(HW_OVERLOAD | HW_ELECTRICAL_SHOCK)
        assert not hw.read(0.0)
        assert hw.state == Lifecycle.ERROR
        assert hw.hardware_error["grip_2"] == HW_OVERLOAD | HW_ELECTRICAL_SHOCK
        assert "'grip_2' (id 2) hardware error: electrical shock, overload" in hw.fault
        assert not hw.write(0.0)  # no commanding in ERROR
        assert hw.recover(), hw.fault
        assert hw.hardware_error["grip_2"] == 0 and chain.servo(2).get("torque_enable") == 1
        assert hw.read(0.0)
        hw.shutdown()


def test_hardware_error_without_reboot_policy_stays_faulted():
    chain = DynamixelChain([1, 2, 3, 4])
    with chain:
        hw = DynamixelChainInterface(chain_config(chain.port, comm={"reboot_on_hardware_error": False}))
        chain.servo(1).inject_hardware_error(HW_OVERLOAD)
        assert not hw.configure()
        assert "hardware error: overload" in hw.fault
        hw.shutdown()


def test_crc_corruption_is_retried_within_budget(emulated):
    chain, hw, _ = emulated
    hw.configure()
    hw.activate()
    hw.retries = 0
    chain.corrupt_next(2)  # within the default budget of 2 retries
    assert hw.read(0.0), hw.fault
    assert hw.retries >= 1


def test_persistent_crc_corruption_faults(emulated):
    chain, hw, _ = emulated
    hw.configure()
    hw.activate()
    chain.corrupt_next(1000)
    assert not hw.read(0.0)
    assert "Incorrect status packet" in hw.fault and "after 3 attempts" in hw.fault


def test_silent_servo_faults_within_bounded_time_naming_it(emulated):
    chain, hw, _ = emulated
    hw.configure()
    hw.activate()
    chain.silence(3)
    start = time.monotonic()
    assert not hw.read(0.0)
    assert time.monotonic() - start < 2.0  # three attempts bounded by the SDK packet timeout (~35 ms each)
    assert "'grip_3' (id 3) did not answer" in hw.fault
    assert not hw.link_ok


def test_dropped_link_faults_and_recovers_when_it_returns(emulated):
    chain, hw, _ = emulated
    hw.configure()
    hw.activate()
    chain.drop_link()
    assert not hw.read(0.0)
    assert not hw.recover()
    assert hw.state == Lifecycle.ERROR
    chain.drop_link(False)
    assert hw.recover(), hw.fault
    assert hw.state == Lifecycle.ACTIVE and hw.read(0.0)


def test_velocity_mode_joint_gets_goal_velocity_in_the_same_chain():
    clock = FakeClock()
    chain = DynamixelChain([1, 2], clock=clock)
    with chain:
        joints = [
            {
                "name": "pos",
                "id": 1,
                "mode": "position",
                "controller": "trajectory",
                "unit": "rad",
                "lower": -1.0,
                "upper": 1.0,
                "max_velocity": 1.0,
            },
            {
                "name": "spin",
                "id": 2,
                "mode": "velocity",
                "controller": "none",
                "unit": "rad",
                "lower": -100.0,
                "upper": 100.0,
                "max_velocity": 3.0,
            },
        ]
        config = {
            "component": "mixed",
            "port": chain.port,
            "joints": joints,
            "comm": {"latency_timer_ms": 60.0},
        }
        hw = DynamixelChainInterface(validate_chain(config))
        assert hw.configure() and hw.activate(), hw.fault
        assert chain.servo(2).get("operating_mode") == 1
        hw.command_velocity["spin"] = 2.0
        seen = chain.packets_seen
        assert hw.write(0.0)
        settle(chain, seen + 2)  # goal position and goal velocity sync writes
        assert chain.servo(2).get("goal_velocity") == math.ceil(2.0 * 60 / (2 * math.pi) / 0.229)
        chain.advance(1.0)
        assert hw.read(1.0)
        assert hw.position["spin"] == pytest.approx(2.0, rel=0.03)
        assert hw.velocity["spin"] == pytest.approx(2.0, rel=0.03)
        hw.shutdown()
