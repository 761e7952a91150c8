"""The real ur-rtde library (RTDEReceiveInterface, RTDEControlInterface, DashboardClient) against
the emulated controller, which runs in its own process: ur-rtde's constructors hold the
interpreter lock while they wait for the controller's answers."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import dashboard_client
import pytest
import rtde_control
import rtde_receive
from tlt_sim.emulators.ur_arm import HOME
from tlt_sim.emulators.ur_controller_config import URControllerConfig
from tlt_sim.emulators.ur_controller_process import URControllerProcess

HOST = "127.0.0.64"  # a loopback address no other test file's emulated arm uses (files run side by side)


class Arm:
    def __init__(self) -> None:
        self.emulator = URControllerProcess(URControllerConfig(host=HOST, unlock_delay_s=0.0)).start()
        self.receive = rtde_receive.RTDEReceiveInterface(HOST)
        self.control = rtde_control.RTDEControlInterface(HOST)

    def wait(self, predicate, what: str, timeout: float = 5.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return
            time.sleep(0.005)
        raise AssertionError(f"timed out waiting for {what}")

    def close(self) -> None:
        for client in (self.control, self.receive):
            try:
                client.disconnect()
            except RuntimeError:
                pass
        # Destroy the clients now, while the emulator still answers, not at interpreter exit.
        self.control = self.receive = None
        self.emulator.close()


@pytest.fixture(scope="module")
def arm() -> Iterator[Arm]:
    a = Arm()
    try:
        yield a
    finally:
        a.close()


@pytest.fixture
def ready(arm: Arm) -> Arm:
    """The arm with no protective stop and the control script running."""
    if arm.receive.isProtectiveStopped():
        arm.emulator.call("unlock_protective_stop")
        arm.wait(lambda: not arm.receive.isProtectiveStopped(), "unlock")
    if not arm.control.isProgramRunning():
        arm.control.reuploadScript()
        arm.wait(arm.control.isProgramRunning, "control script running")
    return arm


def test_receive_reads_the_emulated_state(arm: Arm) -> None:
    assert arm.emulator.call("unknown_names") == []
    assert arm.receive.getActualQ() == pytest.approx(arm.emulator.call("positions"))
    assert arm.receive.getActualTCPPose() == pytest.approx(arm.emulator.call("tcp_pose"))
    assert arm.receive.getRobotMode() == 7
    assert arm.receive.getSafetyMode() == 1
    t0 = arm.receive.getTimestamp()
    arm.wait(lambda: arm.receive.getTimestamp() > t0 + 0.05, "timestamp advancing")


def test_control_script_was_uploaded_and_runs(arm: Arm) -> None:
    assert arm.emulator.call("scripts_received") >= 1
    assert arm.control.isProgramRunning()
    assert arm.receive.getRuntimeState() == 2


def test_movej_reaches_the_target_and_returns_true(ready: Arm) -> None:
    target = list(HOME)
    target[0] += 0.3
    target[4] -= 0.2
    assert ready.control.moveJ(target, 1.5, 4.0) is True
    # moveJ returned on the controller's "done": the arm is there (the receive stream may be a
    # cycle behind the control stream, so it is waited for).
    assert ready.emulator.call("positions") == pytest.approx(target, abs=1e-9)
    ready.wait(lambda: ready.receive.getActualQ() == pytest.approx(target, abs=1e-6), "state at the target")


def test_movel_moves_the_tcp_in_a_straight_line(ready: Arm) -> None:
    start = ready.receive.getActualTCPPose()
    goal = list(start)
    goal[2] -= 0.05
    assert ready.control.moveL(goal, 0.25, 1.2) is True
    assert ready.emulator.call("tcp_pose") == pytest.approx(goal, abs=1e-6)
    ready.wait(lambda: ready.receive.getActualTCPPose() == pytest.approx(goal, abs=1e-5), "TCP at the goal")


def test_servoj_streaming_tracks_a_trajectory(ready: Arm) -> None:
    q0 = ready.receive.getActualQ()
    period = 0.008
    peak = -math.inf
    target = list(q0)
    t0 = time.monotonic()
    for k in range(150):  # a half sine of 0.2 rad over one second at 125 Hz, then hold the end
        target = list(q0)
        target[1] = q0[1] + 0.2 * math.sin(math.pi * min(k * period, 1.0))
        assert ready.control.servoJ(target, 0.0, 0.0, period, 0.03, 2000) is True
        peak = max(peak, ready.receive.getActualQ()[1])
        time.sleep(max(0.0, t0 + (k + 1) * period - time.monotonic()))
    ready.wait(
        lambda: abs(ready.receive.getActualQ()[1] - target[1]) < 1e-3, "arm at the last streamed point"
    )
    assert ready.control.servoStop(5.0) is True
    # The arm went up the sweep with the streamed points (not just to the end point).
    assert peak > q0[1] + 0.15


def test_stopj_stops_an_asynchronous_move(ready: Arm) -> None:
    target = list(ready.receive.getActualQ())
    target[0] -= 1.5
    assert ready.control.moveJ(target, 0.5, 1.0, True) is True
    ready.wait(lambda: abs(ready.receive.getActualQd()[0]) > 0.2, "arm moving")
    ready.control.stopJ(4.0, False)
    ready.wait(lambda: ready.emulator.call("arm_mode") == "idle", "arm at rest")
    ready.wait(lambda: ready.receive.getActualQd() == [0.0] * 6, "rest reported")
    assert abs(ready.receive.getActualQ()[0] - target[0]) > 0.3  # stopped short of the target


def test_speedj_moves_at_the_commanded_speed_until_speed_stop(ready: Arm) -> None:
    assert ready.control.speedJ([0.0, 0.0, 0.0, 0.0, 0.0, 0.3], 3.0, 0.008) is True
    ready.wait(lambda: ready.receive.getActualQd()[5] == pytest.approx(0.3), "joint 6 at 0.3 rad/s")
    assert ready.control.speedStop(3.0) is True
    ready.wait(lambda: ready.receive.getActualQd() == [0.0] * 6, "arm at rest")


def test_protective_stop_makes_movej_fail_at_once(ready: Arm) -> None:
    ready.emulator.call("protective_stop", "test")
    ready.wait(lambda: ready.receive.isProtectiveStopped(), "protective stop reported")
    assert ready.receive.getSafetyMode() == 3
    t0 = time.monotonic()
    assert ready.control.moveJ(list(HOME), 1.0, 1.0) is False
    assert time.monotonic() - t0 < 1.0
    dash = dashboard_client.DashboardClient(HOST)
    dash.connect(2000)
    try:
        assert "PROTECTIVE_STOP" in dash.safetymode()
        dash.unlockProtectiveStop()
    finally:
        dash.disconnect()
    ready.wait(lambda: not ready.receive.isProtectiveStopped(), "protective stop released")
    assert ready.control.reuploadScript()
    ready.wait(ready.control.isProgramRunning, "control script running again")
    assert ready.control.moveJ(list(HOME), 1.5, 4.0) is True


def test_dashboard_answers_what_the_client_checks(arm: Arm) -> None:
    dash = dashboard_client.DashboardClient(HOST)
    dash.connect(2000)
    try:
        assert dash.polyscopeVersion().startswith("5.11.0")
        assert dash.isInRemoteControl() is True
        assert dash.getSerialNumber().isdigit()
    finally:
        dash.disconnect()


def test_second_arm_on_its_own_address() -> None:
    with URControllerProcess(URControllerConfig(host="127.0.0.65", q0=[0.5, -1.0, 1.0, -1.5, -1.5, 0.0])):
        receive = rtde_receive.RTDEReceiveInterface("127.0.0.65")
        try:
            assert receive.getActualQ() == pytest.approx([0.5, -1.0, 1.0, -1.5, -1.5, 0.0])
        finally:
            receive.disconnect()
