"""The real lifter hardware interface (pyserial) against the firmware emulator over a real pty.

Timing assertions use generous margins over the configured bounds so a loaded machine does not
make them flaky; exact timing of the watchdog is tested on a stepped clock in the emulator tests.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator

import pytest
from tlt_sim.emulators.lifter_firmware import Button, FirmwareConfig, LifterFirmware
from tlt_sim.emulators.lifter_pty import PtyFirmwareServer

from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.lifter.config import load_lifter_config
from tlt_drivers.lifter.protocol import FirmwareState, Mode
from tlt_drivers.lifter.serial_interface import CommandRejected, LifterSerialInterface

FW_CONFIG = FirmwareConfig(command_period_s=0.02, init_duration_s=0.05, initial_positions_counts=(20000,) * 4)
PERIOD = 0.02
MARGIN_S = 1.0  # scheduling slack on a shared 2-core machine


@pytest.fixture
def firmware() -> LifterFirmware:
    return LifterFirmware(FW_CONFIG)


@pytest.fixture
def server(firmware: LifterFirmware, tmp_path) -> Iterator[PtyFirmwareServer]:
    with PtyFirmwareServer(firmware, link_path=tmp_path / "lifter") as srv:
        yield srv


def make_config(port: str):
    """The shipped config with bounds widened for a loaded test machine: a driver starved of CPU
    for 0.2 s must not see a link fault that is not there."""
    return dataclasses.replace(load_lifter_config().with_port(port), link_timeout_s=1.0, answer_timeout_s=1.0)


@pytest.fixture
def hw(server: PtyFirmwareServer) -> Iterator[LifterSerialInterface]:
    iface = LifterSerialInterface(make_config(str(server.link_path)))
    yield iface
    iface.shutdown()


def run_cycles(hw: LifterSerialInterface, duration_s: float, until=None) -> float:
    """Read/write at the command rate for ``duration_s`` or until ``until(hw)``; returns elapsed s."""
    start = time.monotonic()
    next_t = start
    while time.monotonic() - start < duration_s:
        now = time.monotonic()
        hw.read(now)
        hw.write(now)
        if until is not None and until(hw):
            break
        next_t += PERIOD
        time.sleep(max(0.0, next_t - time.monotonic()))
    return time.monotonic() - start


def bring_up(hw: LifterSerialInterface, firmware: LifterFirmware) -> None:
    assert hw.configure(), hw.fault
    assert hw.activate()
    run_cycles(hw, 2.0, until=lambda h: h.firmware_state == FirmwareState.HARDWARE_CONTROL)
    assert hw.firmware_state == FirmwareState.HARDWARE_CONTROL


def test_configure_fails_cleanly_without_a_port(tmp_path) -> None:
    iface = LifterSerialInterface(make_config(str(tmp_path / "nothing")))
    assert not iface.configure()
    assert iface.state == Lifecycle.ERROR
    assert "cannot open lifter port" in iface.fault and "nothing" in iface.fault


def test_configure_fails_when_the_firmware_does_not_answer(hw, firmware) -> None:
    firmware.faults.no_answer = True
    start = time.monotonic()
    assert not hw.configure()
    assert time.monotonic() - start < hw.config.answer_timeout_s + MARGIN_S
    assert "did not answer" in hw.fault
    firmware.faults.no_answer = False
    assert hw.recover()
    assert hw.state == Lifecycle.ACTIVE


def test_mode_requests(hw, firmware) -> None:
    bring_up(hw, firmware)
    firmware.press(Button.MOTOR1_CW)
    accepted, reason, state = hw.request_mode(Mode.CRS_CONTROL)
    assert not accepted and "push button" in reason and state == FirmwareState.HARDWARE_CONTROL
    firmware.release_all()
    assert hw.request_mode(Mode.CRS_CONTROL) == (True, "accepted", FirmwareState.CRS_CONTROL)
    assert hw.request_mode(Mode.SAFE)[2] == FirmwareState.SAFE
    assert firmware.state == FirmwareState.SAFE
    assert hw.request_mode(Mode.HARDWARE_CONTROL)[0]
    accepted, reason, _ = hw.request_mode(9)
    assert not accepted and "unknown mode 9" in reason


def test_velocity_commands_move_the_encoders_and_telemetry_follows(hw, firmware) -> None:
    bring_up(hw, firmware)
    assert hw.request_mode(Mode.CRS_CONTROL)[0]
    hw.set_velocity_command([2000, -2000, 0, 1000])
    start_counts = firmware.encoder_counts()
    run_cycles(hw, 0.5)
    moved = [b - a for a, b in zip(start_counts, firmware.encoder_counts(), strict=True)]
    assert moved[0] > 400 and moved[1] < -400 and moved[2] == 0 and moved[3] > 200
    tel = hw.telemetry
    assert tel.state == FirmwareState.CRS_CONTROL
    assert tel.velocities == (2000, -2000, 0, 1000)
    assert abs(tel.positions[0] - firmware.encoder_counts()[0]) < 2000 * 0.2
    assert not tel.watchdog_tripped
    assert hw.commands_sent > 10


def test_out_of_limit_command_is_rejected_naming_joint_and_limit(hw, firmware) -> None:
    bring_up(hw, firmware)
    hw.set_velocity_command([100, 100, 100, 100])
    with pytest.raises(CommandRejected, match=r"lifter_joint_2.*max_velocity_m_s = 0\.05 m/s"):
        hw.set_velocity_command([100, 100, -10001, 100])
    assert hw.command == [100, 100, 100, 100]  # the previous command stays


def test_corrupted_crc_frames_are_counted_and_survived(hw, firmware) -> None:
    bring_up(hw, firmware)
    firmware.faults.corrupt_every_n = 3
    run_cycles(hw, 0.6)
    assert hw.crc_errors >= 3
    assert hw.state == Lifecycle.ACTIVE and hw.link_ok


def test_firmware_watchdog_trips_when_the_driver_stops_writing(hw, firmware) -> None:
    bring_up(hw, firmware)
    assert hw.request_mode(Mode.CRS_CONTROL)[0]
    hw.set_velocity_command([1000] * 4)
    run_cycles(hw, 0.2)
    assert firmware.velocities == [1000] * 4
    deadline = time.monotonic() + 2.0
    hw.deactivate()  # reads continue (state requests), commands stop
    while time.monotonic() < deadline and not (hw.telemetry and hw.telemetry.watchdog_tripped):
        hw.read(time.monotonic())
        time.sleep(PERIOD)
    assert hw.telemetry.watchdog_tripped
    assert hw.telemetry.velocities == (0, 0, 0, 0)


def test_no_answer_is_detected_within_the_link_timeout_then_recovered(hw, firmware) -> None:
    bring_up(hw, firmware)
    firmware.faults.no_answer = True
    elapsed = run_cycles(hw, 5.0, until=lambda h: h.state == Lifecycle.ERROR)
    assert hw.state == Lifecycle.ERROR
    assert "no telemetry" in hw.fault and not hw.link_ok
    assert hw.config.link_timeout_s <= elapsed < hw.config.link_timeout_s + MARGIN_S
    assert not hw.write(time.monotonic())  # no commanding while in fault
    assert not hw.recover()  # still silent
    firmware.faults.no_answer = False
    assert hw.recover()
    assert hw.state == Lifecycle.ACTIVE and hw.link_ok and hw.fault == ""


def test_dropped_link_is_detected_and_recovered_when_it_returns(hw, firmware) -> None:
    bring_up(hw, firmware)
    assert hw.request_mode(Mode.CRS_CONTROL)[0]
    hw.set_velocity_command([1000] * 4)
    run_cycles(hw, 0.1)
    firmware.drop_link(hw.config.link_timeout_s + 1.5)  # long enough to be noticed
    elapsed = run_cycles(hw, 5.0, until=lambda h: h.state == Lifecycle.ERROR)
    assert hw.state == Lifecycle.ERROR and elapsed < hw.config.link_timeout_s + MARGIN_S
    assert firmware.watchdog_tripped and firmware.velocities == [0] * 4  # firmware stopped on its own
    deadline = time.monotonic() + 5.0
    while not hw.recover() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert hw.state == Lifecycle.ACTIVE
    run_cycles(hw, 0.1)
    assert hw.telemetry.state == FirmwareState.CRS_CONTROL


def test_closed_port_is_reported_and_reopened_when_it_returns(hw, firmware, server) -> None:
    bring_up(hw, firmware)
    server.stop()
    run_cycles(hw, 3.0, until=lambda h: h.state == Lifecycle.ERROR)
    assert hw.state == Lifecycle.ERROR and hw.fault
    assert not hw.recover()
    assert "cannot open lifter port" in hw.fault
    with PtyFirmwareServer(firmware, link_path=server.link_path):
        assert hw.recover(), hw.fault
        run_cycles(hw, 0.1)
        assert hw.state == Lifecycle.ACTIVE and hw.link_ok


def test_link_watchdog_counts_in_the_callers_time_base(hw, firmware) -> None:
    """On the twin ``now`` is sim time: while it stands still (the simulation waits for a late
    driver) no amount of wall time is a dead link; once it moves on past the timeout with nothing
    heard, it is."""
    bring_up(hw, firmware)
    firmware.faults.no_answer = True
    sim_now = time.monotonic()  # bring_up ran on the monotonic clock: carry on from there, then stop
    hw.read(sim_now)  # takes whatever was still in flight
    hw.read(sim_now)
    time.sleep(hw.config.link_timeout_s + 0.3)  # wall time passes, the caller's time does not
    assert hw.read(sim_now) and hw.state == Lifecycle.ACTIVE
    assert not hw.read(sim_now + hw.config.link_timeout_s + 0.01)
    assert hw.state == Lifecycle.ERROR and "no telemetry" in hw.fault
