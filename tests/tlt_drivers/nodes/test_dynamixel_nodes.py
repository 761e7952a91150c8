"""Driver nodes in-process against the emulated chains on real ptys: the active_grippers node follows a
FollowJointTrajectory goal and refuses one outside the limits; the end-effector node refuses motion
until its limit-switch calibration, then accepts it; the top_grippers node applies group commands."""

from __future__ import annotations

import math
import threading
import time

import pytest
import rclpy
from builtin_interfaces.msg import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger
from tlt_interfaces.action import FollowJointTrajectory
from tlt_interfaces.msg import (
    EndEffectorState,
    ExecutedTrajectory,
    GripperState,
    HardwareStatus,
    JointTolerance,
)
from tlt_sim.emulators.dynamixel_chain import DynamixelChain
from tlt_sim.emulators.dynamixel_servo import HW_OVERLOAD
from tlt_sim.emulators.mightyzap_chain import MightyZapChain
from trajectory_msgs.msg import JointTrajectoryPoint

from tlt_common.ros.action_client import SerialisedActionClient
from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.stamps import stamp_seconds
from tlt_drivers.dynamixel.config import load_chain, validate_chain
from tlt_drivers.mightyzap.config import load_mightyzap
from tlt_drivers.nodes.active_grippers import GripperGroupNode
from tlt_drivers.nodes.camera_mounts import CameraMountsNode
from tlt_drivers.nodes.ee import EndEffectorNode
from tlt_drivers.nodes.top_grippers import TopGrippersNode

TIMEOUT_S = 15.0
#: the emulators share this process and a 2-core host with other test runs: allow generous reply times
LATENCY_MS = 60.0


class Harness:
    """A private ROS context spinning the driver node and a client node in one background thread."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.client = Node("driver_test_client", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.client)
        self.nodes: list[Node] = []
        self.thread: threading.Thread | None = None
        self.stopping = threading.Event()
        self.closed = False

    def add(self, node: Node) -> Node:
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin(self) -> None:
        def loop() -> None:
            while not self.stopping.is_set():
                self.executor.spin_once(timeout_sec=0.05)

        self.thread = threading.Thread(target=loop, daemon=True)
        self.thread.start()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        # The thread stops before the executor shuts down: Executor.spin racing shutdown() built a
        # wait set with the guard condition shutdown() had just destroyed, and the thread raised.
        self.stopping.set()
        if self.thread is not None:
            self.thread.join(timeout=5.0)  # no control cycle may run while the nodes close their links
        self.executor.shutdown(timeout_sec=5.0)
        for node in self.nodes:
            node.shutdown()
            destroy_node(node)
        destroy_node(self.client)
        rclpy.shutdown(context=self.context)

    @staticmethod
    def wait(predicate, what: str, timeout: float = TIMEOUT_S):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            time.sleep(0.01)
        raise AssertionError(f"timed out waiting for {what}")

    def result(self, future, what: str):
        self.wait(future.done, what)
        return future.result()


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def chain_config(path: str, chain: DynamixelChain) -> dict:
    """A chain's shipped configuration on the emulator's port, with reply times for a busy host."""
    config = load_chain(path)
    config["port"] = chain.port
    config["comm"]["latency_timer_ms"] = LATENCY_MS  # in-process emulator on a busy host
    return config


def send_goal(h: Harness, action: SerialisedActionClient, names, positions, seconds: float):
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = list(names)
    point = JointTrajectoryPoint(positions=list(positions))
    point.time_from_start = Duration(sec=int(seconds), nanosec=int((seconds % 1) * 1e9))
    goal.trajectory.points = [point]
    h.wait(action.server_is_ready, "action server")
    handle = h.result(action.send_goal_async(goal), "goal acceptance")
    return h.result(handle.get_result_async(), "goal result")


def test_active_grippers_follow_a_trajectory_and_refuse_out_of_limit_goals(harness):
    chain = DynamixelChain([1, 2, 3, 4])
    chain.start()
    try:
        config = chain_config("config/hardware/active_grippers.yaml", chain)
        node = harness.add(GripperGroupNode(config, context=harness.context))
        states: list[GripperState] = []
        statuses: list[HardwareStatus] = []
        harness.client.create_subscription(GripperState, "/active_grippers/state", states.append, 50)
        harness.client.create_subscription(
            HardwareStatus, "/active_grippers/hardware_status", statuses.append, 50
        )
        action = SerialisedActionClient(
            harness.client, FollowJointTrajectory, "/active_grippers/follow_joint_trajectory"
        )
        harness.spin()
        names = node.hw.joint_names

        result = send_goal(harness, action, names, [0.6, 0.3, 0.0, 0.0], 1.5)  # 0.4 rad/s of the 1 allowed
        assert result.status == 4 and result.result.error_code == 0, result.result.error_string  # SUCCEEDED
        ticks = chain.servo(1).get("present_position")
        assert ticks == pytest.approx(2048 + 0.6 * 4096 / (2 * math.pi), abs=0.03 * 4096 / (2 * math.pi))

        bad = send_goal(harness, action, names, [2.0, 0.0, 0.0, 0.0], 0.5)
        assert (
            bad.status == 6 and bad.result.error_code == FollowJointTrajectory.Result.INVALID_GOAL
        )  # ABORTED
        assert "'active_gripper_1' position 2.0 above upper limit 1.6" in bad.result.error_string

        harness.wait(lambda: states and states[-1].position[0] > 0.55, "GripperState with the new position")
        assert states[-1].group == "active_grippers" and states[-1].torque_enabled and not states[-1].fault
        harness.wait(
            lambda: statuses and statuses[-1].lifecycle_state == 2 and statuses[-1].link_ok, "status"
        )

        chain.silence(3)
        harness.wait(lambda: states and states[-1].fault, "fault on the state topic")
        assert "'active_gripper_3' (id 3) did not answer" in states[-1].fault_reason
        refused = send_goal(harness, action, names, [0.0, 0.0, 0.0, 0.0], 0.5)
        assert refused.result.error_code == FollowJointTrajectory.Result.HARDWARE_FAULT
        chain.silence(3, False)
        harness.wait(lambda: states and not states[-1].fault, "recovery once the servo answers again")
    finally:
        harness.close()  # the driver lets go of the link before the emulator goes away
        chain.stop()


def test_hardware_error_reported_on_state_then_reboot_recovers(harness):
    chain = DynamixelChain([1, 2, 3, 4])
    chain.start()
    try:
        config = chain_config("config/hardware/active_grippers.yaml", chain)
        harness.add(GripperGroupNode(config, context=harness.context))
        states: list[GripperState] = []
        harness.client.create_subscription(GripperState, "/active_grippers/state", states.append, 50)
        harness.spin()
        harness.wait(lambda: states and states[-1].torque_enabled, "active state")
        chain.servo(2).inject_hardware_error(HW_OVERLOAD)
        harness.wait(lambda: states and states[-1].fault, "fault on the state topic")
        assert list(states[-1].hardware_error) == [0, HW_OVERLOAD, 0, 0]
        assert "'active_gripper_2' (id 2) hardware error: overload" in states[-1].fault_reason
        harness.wait(lambda: states and not states[-1].fault and states[-1].torque_enabled, "reboot recovery")
        assert list(states[-1].hardware_error) == [0, 0, 0, 0]
        assert chain.servo(2).get("hardware_error_status") == 0
    finally:
        harness.close()
        chain.stop()


def test_camera_mounts_new_goal_replaces_running_one_and_joint_states_flow(harness):
    chain = DynamixelChain([1, 2])
    chain.start()
    try:
        config = chain_config("config/hardware/camera_mounts.yaml", chain)
        harness.add(CameraMountsNode(config, context=harness.context))
        joint_states: list[JointState] = []
        harness.client.create_subscription(JointState, "/camera_mounts/joint_states", joint_states.append, 50)
        executed: list[ExecutedTrajectory] = []
        harness.client.create_subscription(
            ExecutedTrajectory, "/camera_mounts/executed_trajectories", executed.append, 50
        )
        action = SerialisedActionClient(
            harness.client, FollowJointTrajectory, "/camera_mounts/follow_joint_trajectory"
        )
        harness.spin()
        names = ["camera_mount_1", "camera_mount_2"]
        slow = FollowJointTrajectory.Goal()
        slow.trajectory.joint_names = names
        slow.trajectory.points = [JointTrajectoryPoint(positions=[1.0, 1.0], time_from_start=Duration(sec=5))]
        harness.wait(action.server_is_ready, "action server")
        first = harness.result(action.send_goal_async(slow), "first goal acceptance")
        first_result = first.get_result_async()
        time.sleep(0.3)
        second = send_goal(harness, action, names, [-0.3, 0.2], 0.5)
        assert second.result.error_code == 0, second.result.error_string
        replaced = harness.result(first_result, "first goal's result")
        assert replaced.status == 6 and replaced.result.error_string == "replaced by a new goal"  # ABORTED
        harness.wait(lambda: joint_states and abs(joint_states[-1].position[0] + 0.3) < 0.02, "joint states")
        assert list(joint_states[-1].name) == names
        # Each goal is recorded as it ended: the replaced one first, aborted well before its 5 s.
        harness.wait(lambda: len(executed) == 2, "two executed-trajectory records")
        assert [(r.outcome, r.planned_s) for r in executed] == [
            (ExecutedTrajectory.OUTCOME_ABORTED, 5.0),
            (ExecutedTrajectory.OUTCOME_SUCCEEDED, 0.5),
        ]
        assert executed[0].error_string == "replaced by a new goal" and list(executed[1].joint_names) == names
        assert stamp_seconds(executed[0].header.stamp) - stamp_seconds(executed[0].started) < 4.0
        assert stamp_seconds(executed[1].header.stamp) - stamp_seconds(executed[1].started) >= 0.5
    finally:
        harness.close()
        chain.stop()


@pytest.mark.parametrize("checked", [True, False], ids=["at_rest", "velocity_not_checked"])
def test_a_camera_mount_goal_succeeds_only_once_the_servos_are_at_rest(harness, checked):
    """A servo's position loop slows as it nears its goal, so it enters a goal tolerance still
    moving; the camera frame taken next expects it at rest. The driver passes the servos' speeds
    to its trajectory controller (``trajectory.goal_velocity_tolerance``, ``goal_settle_s``): the
    goal ends only once they are under it. Without the check the same goal ends at speed."""
    chain = DynamixelChain([1, 2])
    chain.start()
    try:
        config = chain_config("config/hardware/camera_mounts.yaml", chain)
        # A wide goal tolerance: a servo enters it fast, whatever cycles a busy host skips.
        config["trajectory"]["goal_tolerance"] = 0.1
        tolerance = config["trajectory"]["goal_velocity_tolerance"]
        assert tolerance > 0 and config["trajectory"]["goal_settle_s"] > 0
        if not checked:
            config["trajectory"]["goal_velocity_tolerance"] = -1.0
        node = harness.add(CameraMountsNode(config, context=harness.context))
        at_end: list[dict[str, float]] = []
        publish = node.loop.action.executed.publish

        def record_speeds_as_the_goal_ends(*args, **kwargs):  # on the control loop's own cycle
            at_end.append(dict(node.hw.velocity))
            return publish(*args, **kwargs)

        node.loop.action.executed.publish = record_speeds_as_the_goal_ends
        action = SerialisedActionClient(
            harness.client, FollowJointTrajectory, "/camera_mounts/follow_joint_trajectory"
        )
        harness.spin()
        result = send_goal(harness, action, ["camera_mount_1", "camera_mount_2"], [0.6, -0.5], 0.5)
        assert result.status == 4 and result.result.error_code == 0, result.result.error_string
        fastest = max(abs(v) for v in at_end[-1].values())
        if checked:
            assert fastest <= tolerance, at_end
            assert node.hw.position["camera_mount_1"] == pytest.approx(0.6, abs=0.01)
        else:
            assert fastest > 2 * tolerance, at_end
    finally:
        harness.close()
        chain.stop()


def test_cancel_stops_the_goal_where_the_joints_stand(harness):
    chain = DynamixelChain([1, 2])
    chain.start()
    try:
        config = chain_config("config/hardware/camera_mounts.yaml", chain)
        node = harness.add(CameraMountsNode(config, context=harness.context))
        action = SerialisedActionClient(
            harness.client, FollowJointTrajectory, "/camera_mounts/follow_joint_trajectory"
        )
        harness.spin()
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = ["camera_mount_1"]
        goal.trajectory.points = [JointTrajectoryPoint(positions=[1.0], time_from_start=Duration(sec=4))]
        harness.wait(action.server_is_ready, "action server")
        handle = harness.result(action.send_goal_async(goal), "goal acceptance")
        harness.wait(lambda: node.hw.position["camera_mount_1"] > 0.1, "motion under way")
        harness.result(handle.cancel_goal_async(), "cancel reply")
        result = harness.result(handle.get_result_async(), "result")
        assert result.status == 5  # CANCELED
        stopped = node.hw.position["camera_mount_1"]
        time.sleep(0.5)
        assert node.hw.position["camera_mount_1"] == pytest.approx(stopped, abs=0.05)
        assert stopped < 0.9
    finally:
        harness.close()
        chain.stop()


class LimitSwitchFromServo:
    """In-test GPIO: the width limit switch closes when the emulated width servo is at or below ``ticks``."""

    def __init__(self, chain: DynamixelChain, dxl_id: int, ticks: float) -> None:
        self.chain, self.dxl_id, self.ticks = chain, dxl_id, ticks
        self.outputs: dict[str, bool] = {}

    def read_input(self, name: str) -> bool:
        assert name == "ee_x_width_limit"
        return self.chain.servo(self.dxl_id).position <= self.ticks

    def write_output(self, name: str, value: bool) -> None:
        self.outputs[name] = value


def ee_config(port: str) -> dict:
    raw = {
        "component": "ee_x",
        "port": port,
        "rate_hz": 100.0,
        "comm": {"latency_timer_ms": LATENCY_MS},
        "joints": [
            {
                "name": "grasp_left",
                "id": 1,
                "mode": "current_based_position",
                "goal_current_ma": 1000.0,
                "controller": "trajectory",
                "unit": "rad",
                "lower": -0.2,
                "upper": 1.4,
                "max_velocity": 2.0,
            },
            {
                "name": "grasp_right",
                "id": 2,
                "mode": "current_based_position",
                "goal_current_ma": 1000.0,
                "controller": "trajectory",
                "unit": "rad",
                "lower": -0.2,
                "upper": 1.4,
                "max_velocity": 2.0,
            },
            {
                "name": "width",
                "id": 3,
                "mode": "extended_position",
                "controller": "group_position",
                "unit": "m",
                "lead_m_per_rev": 0.01,
                "zero_ticks": 0,
                "lower": 0.0,
                "upper": 0.05,
                "max_velocity": 0.008,
            },
        ],
        "ee": {
            "ars": "ars_x",
            "width_joint": "width",
            "grasp_joints": ["grasp_left", "grasp_right"],
            "limit_switch_input": "ee_x_width_limit",
            "rivet_gun_outputs": ["gun_0", "gun_1"],
            "grasp_effort_threshold": 0.15,
            "calibration": {
                "direction": -1,
                "speed": 0.005,
                "switch_position": 0.0,
                "max_travel": 0.02,
                "timeout_s": 10.0,
                "on_start": False,
            },
        },
    }
    return validate_chain(raw)


def test_ee_refuses_motion_until_calibrated_then_moves(harness):
    chain = DynamixelChain([1, 2, 3])
    chain.start()
    switch_ticks = 2048 - 0.002 / 0.01 * 4096  # 2 mm below where the width servo powers up
    try:
        gpio = LimitSwitchFromServo(chain, 3, switch_ticks)
        node = harness.add(EndEffectorNode(ee_config(chain.port), gpio, context=harness.context))
        states: list[EndEffectorState] = []
        rejected: list[String] = []
        harness.client.create_subscription(EndEffectorState, "/ee_x/state", states.append, 50)
        harness.client.create_subscription(String, "/ee_x/position_command/rejected", rejected.append, 10)
        commands = harness.client.create_publisher(Float64MultiArray, "/ee_x/position_command", 10)
        calibrate = harness.client.create_client(Trigger, "/ee_x/calibrate")
        action = SerialisedActionClient(
            harness.client, FollowJointTrajectory, "/ee_x/follow_joint_trajectory"
        )
        harness.spin()

        harness.wait(lambda: commands.get_subscription_count() > 0, "command subscription")
        commands.publish(Float64MultiArray(data=[0.01]))
        harness.wait(lambda: rejected, "the rejection")
        assert "width joint 'width' is not calibrated" in rejected[-1].data
        refused = send_goal(harness, action, ["grasp_left"], [0.5], 0.3)
        assert refused.result.error_code == FollowJointTrajectory.Result.HARDWARE_FAULT
        assert "not calibrated" in refused.result.error_string
        assert not states or not states[-1].calibrated

        harness.wait(calibrate.service_is_ready, "calibrate service")
        reply = harness.result(calibrate.call_async(Trigger.Request()), "calibrate reply")
        assert reply.success, reply.message
        harness.wait(lambda: states and states[-1].calibrated, "calibrated state")
        assert states[-1].limit_switch
        assert chain.servo(3).position == pytest.approx(switch_ticks, abs=0.001 / 0.01 * 4096)
        assert node.hw.position["width"] == pytest.approx(0.0, abs=0.001)

        commands.publish(Float64MultiArray(data=[0.004]))
        target = chain.servo(3).position + 0.004 / 0.01 * 4096
        harness.wait(lambda: abs(chain.servo(3).position - target) < 20, "width moved 4 mm from the switch")
        ok = send_goal(harness, action, ["grasp_left", "grasp_right"], [0.5, 0.5], 0.4)
        assert ok.result.error_code == 0, ok.result.error_string
        assert not states[-1].part_grasped

        # A strut between the jaws: both grasp servos stop at 0.7 rad, pressing with their goal current.
        for dxl_id in (1, 2):
            chain.servo(dxl_id).set_obstacle(upper=2048 + 0.7 * 4096 / (2 * math.pi))
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = ["grasp_left", "grasp_right"]
        goal.trajectory.points = [JointTrajectoryPoint(positions=[1.2, 1.2], time_from_start=Duration(sec=1))]
        goal.path_tolerance = [JointTolerance(name=n, position=-1.0) for n in ("grasp_left", "grasp_right")]
        goal.goal_tolerance = [JointTolerance(name=n, position=-1.0) for n in ("grasp_left", "grasp_right")]
        handle = harness.result(action.send_goal_async(goal), "grasp goal acceptance")
        assert harness.result(handle.get_result_async(), "grasp result").result.error_code == 0
        harness.wait(lambda: states and states[-1].part_grasped, "part_grasped from servo position and load")
        assert states[-1].position[0] == pytest.approx(0.7, abs=0.01)
    finally:
        harness.close()  # the driver lets go of the link before the emulator goes away
        chain.stop()


def test_ee_keeps_its_calibration_through_a_link_fault_and_seeks_again_after_a_lost_count(harness):
    """A dropped link recovers without a seek (a seek would drag a held part along the slide); a
    width servo rebooted more than a turn from its power-up position lost its multi-turn count
    and refuses motion until calibrated again."""
    chain = DynamixelChain([1, 2, 3])
    chain.start()
    switch_ticks = 2048 - 0.002 / 0.01 * 4096
    try:
        gpio = LimitSwitchFromServo(chain, 3, switch_ticks)
        node = harness.add(EndEffectorNode(ee_config(chain.port), gpio, context=harness.context))
        states: list[EndEffectorState] = []
        harness.client.create_subscription(EndEffectorState, "/ee_x/state", states.append, 50)
        commands = harness.client.create_publisher(Float64MultiArray, "/ee_x/position_command", 10)
        calibrate = harness.client.create_client(Trigger, "/ee_x/calibrate")
        harness.spin()
        harness.wait(calibrate.service_is_ready, "calibrate service")
        assert harness.result(calibrate.call_async(Trigger.Request()), "calibrate reply").success
        harness.wait(lambda: node.calibration.calibrated, "calibrated")
        commands.publish(Float64MultiArray(data=[0.015]))  # a turn and a half from the switch
        harness.wait(lambda: abs(node.hw.position["width"] - 0.015) < 0.0005, "width at 15 mm")

        activations, seen = node.loop.activations, len(states)
        chain.drop_link(True)
        harness.wait(lambda: node.hw.state.name == "ERROR", "the link fault")
        chain.drop_link(False)
        harness.wait(lambda: node.loop.activations > activations, "recovery")
        time.sleep(0.3)
        assert node.calibration.calibrated and all(m.calibrated for m in states[seen:])
        assert node.hw.position["width"] == pytest.approx(0.015, abs=0.0005)

        activations, seen = node.loop.activations, len(states)
        chain.servo(3).inject_hardware_error(HW_OVERLOAD)  # the driver reboots it to clear the error
        harness.wait(lambda: node.loop.activations > activations, "recovery through a reboot")
        harness.wait(lambda: any(not m.calibrated for m in states[seen:]), "the calibration lost")
        assert "lost its multi-turn count" in node.calibration.refusal()
        assert harness.result(calibrate.call_async(Trigger.Request()), "calibrate reply").success
        harness.wait(lambda: node.calibration.calibrated, "calibrated again")
        assert node.hw.position["width"] == pytest.approx(0.0, abs=0.001)  # the seek ended on the switch
    finally:
        harness.close()
        chain.stop()


def grasp(harness: Harness, action, positions) -> None:
    """Grasp joints to ``positions``, pressing on whatever is between the jaws (no tolerances)."""
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = ["grasp_left", "grasp_right"]
    goal.trajectory.points = [
        JointTrajectoryPoint(positions=list(positions), time_from_start=Duration(sec=1))
    ]
    goal.path_tolerance = [JointTolerance(name=n, position=-1.0) for n in ("grasp_left", "grasp_right")]
    goal.goal_tolerance = [JointTolerance(name=n, position=-1.0) for n in ("grasp_left", "grasp_right")]
    handle = harness.result(action.send_goal_async(goal), "grasp goal acceptance")
    assert handle.accepted
    result = harness.result(handle.get_result_async(), "grasp result").result
    assert result.error_code == 0, result.error_string


def test_ee_holding_a_part_waits_for_an_operator_after_a_lost_count_instead_of_seeking(harness):
    """A width servo that reboots and loses its multi-turn count while the jaws hold a part: the
    driver does not seek its limit switch (that would drag the part along the slide). It holds,
    says why as a fault, opens the jaws when told (to put the part down), and seeks once the
    operator chose "when released" and the grippers hold no part."""
    chain = DynamixelChain([1, 2, 3])
    chain.start()
    switch_ticks = 2048 - 0.002 / 0.01 * 4096
    try:
        gpio = LimitSwitchFromServo(chain, 3, switch_ticks)
        config = ee_config(chain.port)
        config["ee"]["calibration"]["on_start"] = True  # as the shipped drivers: a lost count is sought again
        node = harness.add(EndEffectorNode(config, gpio, context=harness.context))
        states: list[EndEffectorState] = []
        rejected: list[String] = []
        harness.client.create_subscription(EndEffectorState, "/ee_x/state", states.append, 50)
        harness.client.create_subscription(String, "/ee_x/position_command/rejected", rejected.append, 10)
        commands = harness.client.create_publisher(Float64MultiArray, "/ee_x/position_command", 10)
        when_released = harness.client.create_client(Trigger, "/ee_x/calibrate_when_released")
        action = SerialisedActionClient(
            harness.client, FollowJointTrajectory, "/ee_x/follow_joint_trajectory"
        )
        harness.spin()
        harness.wait(lambda: node.calibration.calibrated, "calibrated on start")
        harness.wait(lambda: commands.get_subscription_count() > 0, "command subscription")
        commands.publish(Float64MultiArray(data=[0.015]))  # a turn and a half from the switch
        harness.wait(lambda: abs(node.hw.position["width"] - 0.015) < 0.0005, "width at 15 mm")
        harness.wait(action.server_is_ready, "action server")
        for dxl_id in (1, 2):  # a strut between the jaws
            chain.servo(dxl_id).set_obstacle(upper=2048 + 0.7 * 4096 / (2 * math.pi))
        grasp(harness, action, [1.2, 1.2])
        harness.wait(lambda: states and states[-1].part_grasped, "the part held")

        activations, seen = node.loop.activations, len(states)
        chain.servo(3).inject_hardware_error(HW_OVERLOAD)  # the driver reboots it to clear the error
        harness.wait(lambda: node.loop.activations > activations, "recovery through a reboot")
        held = "lost its multi-turn count while a part is held"
        # The servo's hardware error is a fault first (the link's); then the driver's own.
        harness.wait(lambda: any(m.fault and held in m.fault_reason for m in states[seen:]), "the fault")
        fault = next(m for m in states[seen:] if m.fault and held in m.fault_reason)
        assert "/ee_x/calibrate_when_released" in fault.fault_reason and not fault.calibrated
        assert node.calibration.state.name == "WAITING"
        stands = chain.servo(3).position
        time.sleep(0.5)
        assert chain.servo(3).position == pytest.approx(stands, abs=5)  # no seek with the part held
        assert node.calibration.state.name == "WAITING" and states[-1].fault

        reply = harness.result(when_released.call_async(Trigger.Request()), "the operator's choice")
        assert reply.success and "once the part is put down" in reply.message, reply.message
        time.sleep(0.3)
        assert node.calibration.state.name == "WAITING"  # the part is still held
        assert chain.servo(3).position == pytest.approx(stands, abs=5)
        commands.publish(Float64MultiArray(data=[0.01]))
        harness.wait(lambda: rejected, "the width command refused")
        assert "waiting for an operator" in rejected[-1].data, rejected[-1].data
        for dxl_id in (1, 2):  # the part is taken off the jaws as they open
            chain.servo(dxl_id).set_obstacle()
        grasp(harness, action, [0.0, 0.0])  # the jaws may move while the width may not
        harness.wait(lambda: node.calibration.calibrated, "calibrated once no part is held")
        assert node.hw.position["width"] == pytest.approx(0.0, abs=0.001)  # the seek ended on the switch
        harness.wait(lambda: not states[-1].fault, "the fault cleared")
    finally:
        harness.close()
        chain.stop()


def test_ee_calibration_fails_with_reason_when_switch_never_closes(harness):
    chain = DynamixelChain([1, 2, 3])
    chain.start()
    try:
        gpio = LimitSwitchFromServo(chain, 3, -1e9)  # a broken switch
        config = ee_config(chain.port)
        config["ee"]["calibration"]["max_travel"] = 0.003
        node = harness.add(EndEffectorNode(config, gpio, context=harness.context))
        calibrate = harness.client.create_client(Trigger, "/ee_x/calibrate")
        harness.spin()
        harness.wait(calibrate.service_is_ready, "calibrate service")
        assert harness.result(calibrate.call_async(Trigger.Request()), "calibrate reply").success
        harness.wait(lambda: node.calibration.state.name == "FAILED", "calibration failure")
        assert "limit switch not reached" in node.calibration.refusal()
    finally:
        harness.close()  # the driver lets go of the link before the emulator goes away
        chain.stop()


def top_grippers_node(chain: MightyZapChain, harness: Harness) -> TopGrippersNode:
    """The shipped Top Grippers' driver on ``chain``'s port, with room for a loaded machine."""
    config = load_mightyzap("config/hardware/top_grippers.yaml")
    config["port"] = chain.port
    config["comm"]["response_timeout_s"] = LATENCY_MS * 3 / 1000.0
    return TopGrippersNode(config, context=harness.context)


def test_top_grippers_apply_group_commands_and_reject_out_of_limit(harness):
    chain = MightyZapChain([1, 2, 3, 4])
    chain.start()
    try:
        harness.add(top_grippers_node(chain, harness))
        states: list[GripperState] = []
        rejected: list[String] = []
        harness.client.create_subscription(GripperState, "/top_grippers/state", states.append, 50)
        harness.client.create_subscription(
            String, "/top_grippers/position_command/rejected", rejected.append, 10
        )
        commands = harness.client.create_publisher(Float64MultiArray, "/top_grippers/position_command", 10)
        harness.spin()
        harness.wait(lambda: commands.get_subscription_count() > 0, "command subscription")
        commands.publish(Float64MultiArray(data=[0.025, 0.025, 0.0, 0.03]))
        harness.wait(lambda: rejected, "the rejection")
        assert "joint 'top_gripper_4': command 0.03 is above the upper limit 0.027" in rejected[-1].data
        commands.publish(Float64MultiArray(data=[0.025, 0.025, 0.0, 0.0]))
        harness.wait(lambda: states and abs(states[-1].position[0] - 0.025) < 0.0005, "stroke reached")
        assert states[-1].engaged == [True, True, False, False] and not states[-1].fault
    finally:
        harness.close()  # the driver lets go of the link before the emulator goes away
        chain.stop()


@pytest.mark.parametrize("step", ["loop time went back", "ROS time stands still"])
def test_states_go_on_when_time_steps(harness, stop_ros_time, step):
    # A restarted twin's clock leaves the last state's time ahead of now: waiting for the clock to
    # come back to it silenced the node for that long. On hardware ROS time is the system clock;
    # set back, it stands still for a timer on it, which stopped the whole loop (commands, states,
    # recovery) for as long as the step.
    chain = MightyZapChain([1, 2, 3, 4])
    chain.start()
    try:
        node = harness.add(top_grippers_node(chain, harness))
        states: list[GripperState] = []
        harness.client.create_subscription(GripperState, "/top_grippers/state", states.append, 50)
        harness.spin()
        harness.wait(lambda: states, "a state")
        if step == "loop time went back":
            node.loop._last_state = node.loop.now() + 3600.0
        else:
            stop_ros_time(node)
        seen = len(states)
        harness.wait(lambda: len(states) >= seen + 3, f"states ({step})")
    finally:
        harness.close()  # the driver lets go of the link before the emulator goes away
        chain.stop()
