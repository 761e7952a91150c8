"""The pyserial MightyZAP driver against the emulated IR-USB02 chain over a pseudo-terminal."""

from __future__ import annotations

import time

import pytest
from tlt_sim.emulators.mightyzap_chain import ERR_OVERLOAD, MightyZapChain

from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.mightyzap.chain_interface import MightyZapChainInterface
from tlt_drivers.mightyzap.config import validate_mightyzap


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def config(port: str, **extra) -> dict:
    return validate_mightyzap(
        {
            "component": "top_grippers",
            "port": port,
            "stroke_m": 0.027,
            "actuators": [
                {"name": f"top_gripper_{i}", "id": i, "lower": 0.0, "upper": 0.027, "engaged_above": 0.02}
                for i in (1, 2, 3, 4)
            ],
            "comm": {"response_timeout_s": 0.15},  # the emulator shares this process and a busy host
            **extra,
        }
    )


@pytest.fixture
def emulated():
    clock = FakeClock()
    chain = MightyZapChain([1, 2, 3, 4], clock=clock)
    chain.start()
    hw = MightyZapChainInterface(config(chain.port))
    yield chain, hw, clock
    hw.shutdown()
    chain.stop()


def settle(chain, seen):
    deadline = time.monotonic() + 2.0
    while chain.packets_seen < seen and time.monotonic() < deadline:
        time.sleep(0.001)


def test_configure_activate_sets_return_mode_and_force(emulated):
    chain, hw, _ = emulated
    chain.actuator(3).mem[0x10] = 0  # one actuator left in "echo only" mode
    assert hw.configure(), hw.fault
    assert hw.activate(), hw.fault
    assert [chain.actuator(i).get(0x10) for i in (1, 2, 3, 4)] == [1, 1, 1, 1]
    assert all(chain.actuator(i).get(0x80) == 1 for i in (1, 2, 3, 4))


def test_return_mode_2_configured_and_writes_checked(emulated):
    chain, _, _ = emulated
    hw = MightyZapChainInterface(config(chain.port, feedback_return_mode=2))
    assert hw.configure() and hw.activate(), hw.fault
    assert chain.actuator(2).get(0x10) == 2
    hw.shutdown()


def test_symmetric_store_moves_all_and_read_reports_metres(emulated):
    chain, hw, clock = emulated
    hw.configure()
    hw.activate()
    hw.command.update({"top_gripper_1": 0.0135, "top_gripper_4": 0.027})
    seen = chain.packets_seen
    assert hw.write(0.0)
    settle(chain, seen + 1)
    clock.t = 3.0
    assert hw.read(3.0), hw.fault
    assert hw.position["top_gripper_1"] == pytest.approx(0.0135, abs=0.027 / 4095)
    assert hw.position["top_gripper_4"] == pytest.approx(0.027)
    assert hw.position["top_gripper_2"] == 0.0


def test_overload_reported_then_restart_recovers(emulated):
    chain, hw, clock = emulated
    hw.configure()
    hw.activate()
    chain.actuator(2).set_obstacle(upper=1000)
    hw.command["top_gripper_2"] = 0.02
    seen = chain.packets_seen
    hw.write(0.0)
    settle(chain, seen + 1)
    clock.t = 2.0
    assert not hw.read(2.0)
    assert hw.state == Lifecycle.ERROR and "'top_gripper_2' (id 2): overload" in hw.fault
    assert hw.hardware_error["top_gripper_2"] & ERR_OVERLOAD
    chain.actuator(2).set_obstacle()
    assert hw.recover(), hw.fault
    assert hw.hardware_error["top_gripper_2"] == 0 and chain.actuator(2).get(0x80) == 1


def test_corrupted_feedback_retried_then_fault(emulated):
    chain, hw, _ = emulated
    hw.configure()
    hw.activate()
    hw.retries = 0
    chain.corrupt_next(1)
    assert hw.read(0.0) and hw.retries == 1
    chain.corrupt_next(100)
    assert not hw.read(0.0) and "checksum mismatch" in hw.fault


def test_silent_actuator_faults_in_bounded_time_and_link_return_recovers(emulated):
    chain, hw, _ = emulated
    hw.configure()
    hw.activate()
    chain.silence(4)
    start = time.monotonic()
    assert not hw.read(0.0)
    assert time.monotonic() - start < 2.0
    assert "'top_gripper_4' (id 4)" in hw.fault and "no feedback" in hw.fault
    chain.drop_link()
    assert not hw.recover()
    chain.drop_link(False)
    chain.silence(4, False)
    assert hw.recover(), hw.fault
    assert hw.read(0.0)


def test_bad_limits_rejected_by_schema():
    from tlt_common.config_schema import ConfigError

    with pytest.raises(ConfigError, match=r"actuators\[0\]"):
        validate_mightyzap(
            {
                "component": "t",
                "port": "/dev/null",
                "stroke_m": 0.027,
                "actuators": [{"name": "a", "id": 1, "lower": 0.0, "upper": 0.05, "engaged_above": 0.01}],
            }
        )
