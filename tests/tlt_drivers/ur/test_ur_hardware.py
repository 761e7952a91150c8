"""The UR hardware interface (real ur-rtde) against the emulated controller in its own process:
lifecycle, moves, servo streaming, joint limits, protective stop, stopped program, dropped link
and a silent controller, each detected within a bounded time and recovered from."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator

import pytest
from tlt_sim.emulators.ur_controller_config import URControllerConfig
from tlt_sim.emulators.ur_controller_process import URControllerProcess

from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.ur.config import CONFIG_DIR, load_ur_config
from tlt_drivers.ur.hardware import JointLimitError, MotionRefused, URHardware
from tlt_drivers.ur.rtde_link import probe_rtde

HOST = "127.0.0.62"  # a loopback address no other test file's emulated arm uses (files run side by side)


class Rig:
    def __init__(self) -> None:
        self.emulator = URControllerProcess(URControllerConfig(host=HOST, unlock_delay_s=0.0)).start()
        config = load_ur_config(CONFIG_DIR / "ur_x.yaml")
        self.config = dataclasses.replace(config, host=HOST, link_timeout_s=0.3, probe_timeout_s=0.3)
        self.hw = URHardware(self.config)

    def cycle_until(self, predicate, what: str, timeout: float = 5.0) -> float:
        """Run read cycles until ``predicate()``; returns the time it took."""
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            self.hw.read(time.monotonic())
            if predicate():
                return time.monotonic() - t0
            time.sleep(0.004)
        raise AssertionError(f"timed out waiting for {what} (fault: {self.hw.fault!r})")

    def recover(self, timeout: float = 5.0) -> None:
        t0 = time.monotonic()
        while not self.hw.try_recover():
            assert time.monotonic() - t0 < timeout, f"no recovery: {self.hw.recovery_blocker()}"
            time.sleep(0.05)
        assert self.hw.state == Lifecycle.ACTIVE and self.hw.fault == ""

    def close(self) -> None:
        self.hw.shutdown()
        self.emulator.close()


@pytest.fixture(scope="module")
def rig() -> Iterator[Rig]:
    r = Rig()
    try:
        yield r
    finally:
        r.close()


@pytest.fixture
def active(rig: Rig) -> Rig:
    if rig.hw.state == Lifecycle.UNCONFIGURED:
        assert rig.hw.configure(), rig.hw.fault
        assert rig.hw.activate(), rig.hw.fault
    if rig.hw.state == Lifecycle.ERROR:
        rig.emulator.call("unlock_protective_stop")
        rig.recover()
    return rig


def test_probe_reports_an_absent_controller_quickly() -> None:
    t0 = time.monotonic()
    problem = probe_rtde("127.0.0.9", timeout=0.3)
    assert problem and "127.0.0.9" in problem
    assert time.monotonic() - t0 < 2.0


def test_configure_and_activate_start_the_control_script(rig: Rig) -> None:
    assert rig.hw.configure(), rig.hw.fault
    assert rig.hw.state == Lifecycle.INACTIVE and rig.hw.link_ok
    assert rig.hw.activate(), rig.hw.fault
    assert rig.hw.reading.program_running
    assert rig.emulator.call("program_running")
    assert list(rig.hw.positions) == list(rig.config.joint_names)


def test_move_joints_reaches_the_target(active: Rig) -> None:
    target = list(active.hw.reading.q)
    target[0] += 0.2
    active.hw.move_joints(target, 1.5, 4.0)
    active.cycle_until(lambda: not active.hw.move_running(), "move finished")
    active.cycle_until(lambda: active.hw.reading.q[0] == pytest.approx(target[0], abs=1e-6), "target reached")


def test_commands_outside_the_joint_limits_are_rejected_naming_joint_and_limit(active: Rig) -> None:
    target = list(active.hw.reading.q)
    target[2] = 3.5  # elbow limit is +-3.1416 in ur_x.yaml
    with pytest.raises(JointLimitError, match=r"'ur_x_elbow_joint'.*upper limit 3\.14"):
        active.hw.move_joints(target)
    target[2] = active.hw.reading.q[2]
    target[0] = -7.0
    with pytest.raises(JointLimitError, match=r"'ur_x_shoulder_pan_joint'.*lower limit -6\.28"):
        active.hw.set_servo_target(target)
    assert active.emulator.call("arm_mode") == "idle"


def test_servo_streaming_follows_targets_each_cycle(active: Rig) -> None:
    q0 = list(active.hw.reading.q)
    period = 1.0 / active.config.control_rate_hz
    for k in range(60):
        target = list(q0)
        target[3] = q0[3] + 0.002 * k
        active.hw.read(time.monotonic())
        active.hw.set_servo_target(target)
        assert active.hw.write(time.monotonic()), active.hw.fault
        time.sleep(period)
    active.hw.set_servo_target(None)
    active.hw.write(time.monotonic())
    active.cycle_until(lambda: abs(active.hw.reading.q[3] - (q0[3] + 0.118)) < 0.01, "servo target reached")


def test_protective_stop_is_reported_refuses_motion_until_cleared(active: Rig) -> None:
    target = list(active.hw.reading.q)
    target[0] -= 1.0
    active.hw.move_joints(target, 0.5, 1.0)
    active.emulator.call("protective_stop", "collision")
    active.cycle_until(lambda: active.hw.state == Lifecycle.ERROR, "protective stop detected", timeout=1.0)
    assert "protective stop" in active.hw.fault
    with pytest.raises(MotionRefused, match="not active"):
        active.hw.move_joints(target)
    assert not active.hw.try_recover()  # still stopped: stays in ERROR
    assert active.hw.recovery_blocker() == "protective stop still active (unlock it)"
    assert active.hw.unlock_protective_stop() == "Protective stop releasing"
    active.recover()
    assert active.emulator.call("program_running")


def test_stopped_program_is_detected_and_restarted(active: Rig) -> None:
    active.emulator.call("stop_program", "stopped on the pendant")
    active.cycle_until(lambda: active.hw.state == Lifecycle.ERROR, "program stop detected", timeout=1.0)
    assert "control script" in active.hw.fault
    active.recover()
    assert active.emulator.call("program_running")


def test_dropped_link_is_detected_within_the_link_timeout_and_reconnects(active: Rig) -> None:
    active.emulator.call("drop_link")
    took = active.cycle_until(lambda: active.hw.state == Lifecycle.ERROR, "link loss detected", timeout=3.0)
    assert took < active.config.link_timeout_s + 1.0
    assert not active.hw.link_ok
    assert not active.hw.try_recover()
    assert "unreachable" in active.hw.recovery_blocker()
    active.emulator.call("restore_link")
    # ur-rtde's control interface makes one reconnect attempt of its own; the link waits it out.
    active.recover(timeout=active.hw.link.control_settle_s + 5.0)
    target = list(active.hw.reading.q)
    target[5] += 0.1
    active.hw.move_joints(target, 1.5, 4.0, wait=True)
    active.cycle_until(lambda: abs(active.hw.reading.q[5] - target[5]) < 1e-6, "moved after reconnect")


def test_silent_controller_is_detected_by_stale_data(active: Rig) -> None:
    active.emulator.call("set_no_answer", True)
    try:
        took = active.cycle_until(lambda: active.hw.state == Lifecycle.ERROR, "silence detected", timeout=3.0)
        assert took >= active.config.link_timeout_s * 0.9
        assert "no data from the controller" in active.hw.fault
        assert "did not answer" in active.hw.recovery_blocker()
    finally:
        active.emulator.call("set_no_answer", False)
    active.recover()
