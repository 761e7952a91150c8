"""The ``lifter`` ROS node in-process, against the firmware emulator on a real pty: LifterState and
HardwareStatus published, SetLifterMode, FollowJointTrajectory raising the lifter to tolerance,
goals refused with the reason, a link fault aborting a running goal, and every goal recorded once
it ended."""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Iterator

import pytest
import rclpy
from builtin_interfaces.msg import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from tlt_interfaces.action import FollowJointTrajectory
from tlt_interfaces.msg import ExecutedTrajectory, HardwareStatus, LifterState
from tlt_interfaces.srv import SetLifterMode
from tlt_sim.emulators.lifter_firmware import Button, FirmwareConfig, LifterFirmware
from tlt_sim.emulators.lifter_pty import PtyFirmwareServer
from trajectory_msgs.msg import JointTrajectoryPoint

from tlt_common.ros.action_client import SerialisedActionClient
from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.stamps import stamp_seconds
from tlt_drivers.lifter.config import load_lifter_config
from tlt_drivers.lifter.node import STATE_TOPIC, STATUS_TOPIC, LifterNode, main

CPM = 200_000.0
START_M = 0.1
TIMEOUT_S = 15.0


class Harness:
    def __init__(self, tmp_path) -> None:
        self.firmware = LifterFirmware(
            FirmwareConfig(command_period_s=0.02, init_duration_s=0.05, initial_positions_counts=(20000,) * 4)
        )
        self.server = PtyFirmwareServer(self.firmware, link_path=tmp_path / "lifter")
        self.server.start()
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        # bounds widened for a loaded test machine (a starved executor is not a link fault)
        config = dataclasses.replace(
            load_lifter_config().with_port(str(self.server.link_path)),
            link_timeout_s=1.0,
            answer_timeout_s=1.0,
            reconnect_period_s=0.5,
        )
        self.node = LifterNode(config, context=self.context)
        self.client = Node("lifter_test_client", context=self.context)
        self.states: list[LifterState] = []
        self.statuses: list[HardwareStatus] = []
        self.client.create_subscription(LifterState, STATE_TOPIC, self.states.append, 50)
        self.client.create_subscription(HardwareStatus, STATUS_TOPIC, self.statuses.append, 10)
        self.executed: list[ExecutedTrajectory] = []
        self.client.create_subscription(
            ExecutedTrajectory, "lifter/executed_trajectories", self.executed.append, 50
        )
        self.set_mode = self.client.create_client(SetLifterMode, "lifter/set_mode")
        self.action = SerialisedActionClient(
            self.client, FollowJointTrajectory, "lifter/follow_joint_trajectory"
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.client)
        self.spin_error: BaseException | None = None
        self.stopping = threading.Event()
        self.action_seen = self.service_seen = False
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        try:
            while not self.stopping.is_set():
                self.executor.spin_once(timeout_sec=0.05)
        except BaseException as exc:  # surfaced by wait(), so a dead executor is not a mystery timeout
            self.spin_error = exc
            raise

    def wait(self, predicate, what: str, timeout: float = TIMEOUT_S):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            if self.spin_error is not None:
                raise AssertionError(f"executor died while waiting for {what}") from self.spin_error
            time.sleep(0.01)
        raise AssertionError(f"timed out waiting for {what}")

    def wait_future(self, future, what: str):
        self.wait(future.done, what)
        return future.result()

    def request_mode(self, mode: int) -> SetLifterMode.Response:
        if not self.service_seen:
            self.service_seen = self.wait(lambda: self.set_mode.service_is_ready(), "set_mode service")
        return self.wait_future(self.set_mode.call_async(SetLifterMode.Request(mode=mode)), "set_mode reply")

    def send_goal(self, positions, seconds: float, names=None):
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = names or [f"lifter_joint_{i}" for i in range(4)]
        point = JointTrajectoryPoint(positions=list(positions))
        point.time_from_start = Duration(sec=int(seconds), nanosec=int((seconds % 1) * 1e9))
        goal.trajectory.points = [point]
        if not self.action_seen:
            # once only: under load Fast DDS has been seen to report a matched server unready later
            self.action_seen = self.wait(lambda: self.action.server_is_ready(), "action server")
        handle = self.wait_future(self.action.send_goal_async(goal), "goal acceptance")
        return handle, handle.get_result_async()

    def close(self) -> None:
        self.stopping.set()
        self.thread.join(timeout=5)
        self.executor.shutdown()
        self.node.shutdown()
        destroy_node(self.node)
        destroy_node(self.client)
        rclpy.try_shutdown(context=self.context)
        self.server.stop()


@pytest.fixture
def harness(tmp_path) -> Iterator[Harness]:
    h = Harness(tmp_path)
    try:
        yield h
    finally:
        h.close()


def in_hardware_control(h: Harness) -> None:
    h.wait(
        lambda: h.states and h.states[-1].state == LifterState.STATE_HARDWARE_CONTROL,
        "LifterState in Hardware Control",
    )


def test_state_published_and_mode_service(harness: Harness) -> None:
    h = harness
    in_hardware_control(h)
    msg = h.states[-1]
    assert list(msg.joint_names) == [f"lifter_joint_{i}" for i in range(4)]
    assert list(msg.encoder_counts) == [20000] * 4
    assert list(msg.encoder_positions) == pytest.approx([START_M] * 4)
    assert msg.link_ok and msg.fault == ""
    status = h.wait(lambda: h.statuses and h.statuses[-1], "HardwareStatus")
    assert status.component == "lifter" and status.lifecycle_state == HardwareStatus.LIFECYCLE_ACTIVE
    reply = h.request_mode(SetLifterMode.Request.MODE_CRS_CONTROL)
    assert reply.success and reply.state == LifterState.STATE_CRS_CONTROL
    h.wait(lambda: h.states[-1].state == LifterState.STATE_CRS_CONTROL, "CRS Control in LifterState")
    reply = h.request_mode(SetLifterMode.Request.MODE_SAFE)
    assert reply.success and reply.state == LifterState.STATE_SAFE
    reply = h.request_mode(42)
    assert not reply.success and "unknown mode 42" in reply.reason


def test_trajectory_raises_the_lifter_within_tolerance(harness: Harness) -> None:
    h = harness
    in_hardware_control(h)
    # refused while not in CRS Control, with the reason
    handle, result = h.send_goal([0.12] * 4, 1.0)
    res = h.wait_future(result, "result of a goal outside CRS Control").result
    assert res.error_code == FollowJointTrajectory.Result.INVALID_GOAL
    assert "request CRS Control first" in res.error_string
    assert h.request_mode(SetLifterMode.Request.MODE_CRS_CONTROL).success
    # out of limits: refused naming the joint and the limit
    handle, result = h.send_goal([0.12, 0.12, 1.5, 0.12], 60.0)
    res = h.wait_future(result, "result of an out-of-limit goal").result
    assert res.error_code == FollowJointTrajectory.Result.INVALID_GOAL
    assert "lifter_joint_2" in res.error_string and "max_position_m = 1.2" in res.error_string
    # a good goal: 2 cm up in 1 s
    handle, result = h.send_goal([0.12] * 4, 1.0)
    assert handle.accepted
    wrapped = h.wait_future(result, "trajectory result")
    assert wrapped.result.error_code == FollowJointTrajectory.Result.SUCCESSFUL, wrapped.result.error_string
    counts = h.firmware.encoder_counts()
    assert all(abs(c / CPM - 0.12) <= 0.002 + 0.001 for c in counts), counts
    state = h.wait(lambda: h.states[-1], "state")
    assert all(abs(p - 0.12) < 0.004 for p in state.encoder_positions)


def test_link_fault_aborts_the_running_goal_and_is_reported(harness: Harness) -> None:
    h = harness
    in_hardware_control(h)
    assert h.request_mode(SetLifterMode.Request.MODE_CRS_CONTROL).success
    # slow enough that 1 s of stale telemetry stays inside the path tolerance
    handle, result = h.send_goal([0.3] * 4, 40.0)
    assert handle.accepted
    h.wait(lambda: h.firmware.velocities[0] > 0, "lifter moving")
    h.firmware.faults.no_answer = True
    res = h.wait_future(result, "abort on link fault").result
    assert res.error_code == FollowJointTrajectory.Result.HARDWARE_FAULT
    assert "no telemetry" in res.error_string
    bad = h.wait(lambda: not h.states[-1].link_ok and h.states[-1], "fault in LifterState")
    assert "no telemetry" in bad.fault
    h.wait(
        lambda: h.statuses and h.statuses[-1].lifecycle_state == HardwareStatus.LIFECYCLE_ERROR,
        "ERROR in HardwareStatus",
        timeout=2.0,
    )
    assert "no telemetry" in h.statuses[-1].fault and not h.statuses[-1].link_ok
    h.firmware.faults.no_answer = False
    h.wait(lambda: h.states[-1].link_ok, "link recovered", timeout=10.0)


def test_main_refuses_a_bad_config(tmp_path, capsys) -> None:
    bad = tmp_path / "lifter.yaml"
    bad.write_text("port: /dev/null\ncommand_rate_hz: 50\ncontroller: {}\njoints: []\n")
    assert main(["--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "lifter.yaml" in err and "joints" in err and "expected 4 joints" in err


def test_new_goal_replaces_the_running_one_and_cancel_stops(harness: Harness) -> None:
    h = harness
    in_hardware_control(h)
    assert h.request_mode(SetLifterMode.Request.MODE_CRS_CONTROL).success
    _first, first_result = h.send_goal([0.3] * 4, 10.0)
    h.wait(lambda: h.firmware.velocities[0] > 0, "lifter moving up")
    _second, second_result = h.send_goal([0.09] * 4, 1.0)
    res = h.wait_future(first_result, "first goal's end").result
    assert res.error_code == FollowJointTrajectory.Result.INVALID_GOAL and "preempted" in res.error_string
    h.wait(lambda: h.firmware.velocities[0] < 0, "lifter moving down for the new goal")
    assert h.wait_future(second_result, "second goal").result.error_code == 0
    third, third_result = h.send_goal([0.3] * 4, 10.0)
    h.wait(lambda: h.firmware.velocities[0] > 0, "lifter moving up again")
    h.wait_future(third.cancel_goal_async(), "cancel reply")
    h.wait_future(third_result, "cancelled goal")
    h.wait(lambda: h.firmware.velocities == [0, 0, 0, 0], "lifter stopped after cancel")
    # Each goal's record: what it asked for, how long it ran, how it ended.
    h.wait(lambda: len(h.executed) == 3, "three executed-trajectory records")
    first, second, third = h.executed
    record = ExecutedTrajectory
    assert [r.outcome for r in h.executed] == [
        record.OUTCOME_ABORTED,
        record.OUTCOME_SUCCEEDED,
        record.OUTCOME_CANCELED,
    ]
    assert [r.planned_s for r in h.executed] == pytest.approx([10.0, 1.0, 10.0])
    assert "preempted" in first.error_string and second.error_code == 0
    assert list(second.joint_names) == [f"lifter_joint_{i}" for i in range(4)]

    def took(r: ExecutedTrajectory) -> float:
        return stamp_seconds(r.header.stamp) - stamp_seconds(r.started)

    assert 1.0 <= took(second) < 5.0
    assert took(first) < 10.0 and took(third) < 10.0  # both ended early


def test_button_press_during_a_goal_aborts_it(harness: Harness) -> None:
    h = harness
    in_hardware_control(h)
    assert h.request_mode(SetLifterMode.Request.MODE_CRS_CONTROL).success
    _, result = h.send_goal([0.3] * 4, 10.0)
    h.wait(lambda: h.firmware.velocities[0] > 0, "lifter moving up")
    h.firmware.set_potentiometer(0.0)
    h.firmware.press(Button.MOTOR0_CCW)
    res = h.wait_future(result, "abort when the firmware leaves CRS Control").result
    assert res.error_code == FollowJointTrajectory.Result.HARDWARE_FAULT
    assert "left CRS Control (now HARDWARE_CONTROL)" in res.error_string


def test_the_command_stream_goes_on_while_ros_time_stands_still(harness: Harness, stop_ros_time) -> None:
    # On hardware ROS time is the system clock; set back, it stands still for a timer on it. The
    # 50 Hz stream stopped with it and the firmware's 40 ms watchdog zeroed the motors.
    h = harness
    in_hardware_control(h)
    frames = h.firmware.frames_received
    stop_ros_time(h.node)
    seen = len(h.states)
    h.wait(lambda: len(h.states) >= seen + 25, "LifterState while ROS time stands still")
    # the firmware's thread reads the pty on its own schedule: the last frame written may be unread yet
    h.wait(lambda: h.firmware.frames_received >= frames + 25, "25 command frames at the firmware", 2.0)
    assert not h.firmware.watchdog_tripped
