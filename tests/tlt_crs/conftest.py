"""Stand-ins for what the CRS talks to, on real ROS interfaces, and helpers to tick CRS subtrees.

* ``ArsStandIn``: action servers of one ARS (add_cross_frame, add_member, affix_member,
  foundation_rivet), its GroundCommand service, its SetBlackboardValue service (the ARS's own
  :class:`tlt_ars.ground_writes.GroundWrites` over its configuration), and its end effector's and
  arm's states. It
  records every request it gets, presents parts to ``/crs/inspect_part`` as the ARS of §V.C.3
  does (fetching another part after a failed inspection), and can be told to fail, to be slow, or
  to honour Pause. These are what the ARS issue replaces.
* ``VisionStandIn``: ``/vision/inspect_part`` and ``/vision/inspect_bay`` with scripted verdicts.
* ``LifterStandIn``, ``GripperStandIn``, ``CameraStandIn``: small stand-ins for the driver nodes'
  topics, services and trajectory actions (``LifterState`` with encoder positions and the
  firmware state, ``SetLifterMode``, ``GripperState.engaged`` from the commanded positions).
  Trajectories finish after ``time_scale`` times their duration so a bay builds in seconds.
"""

from __future__ import annotations

import gc
import math
import threading
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import py_trees
import pytest
import rclpy
from py_trees.common import Status
from rclpy._rclpy_pybind11 import InvalidHandle
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node

from tlt_common import ros_names
from tlt_common.ros.executor_stop import stop_executor
from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.readiness import ReadinessPublisher

REPO = Path(__file__).resolve().parents[2]
ONE_BAY = REPO / "missions" / "one_bay.yaml"
TWO_BAY = REPO / "missions" / "two_bay.yaml"
REGISTRY = REPO / "config" / "crs" / "writable_blackboard.yaml"
CLOSING = threading.Event()  # set while a rig closes: every stand-in callback returns promptly
NEVER_AWAITED = "coroutine 'ActionServer._execute_goal' was never awaited"


@dataclass
class Request:
    ars: str
    request: str
    member_id: str
    at: float
    outcome: str = "running"
    joint: str = ""  # the joint an Affix Member names (an operator's retry)


@dataclass
class Recorder:
    requests: list[Request] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, r: Request) -> Request:
        with self.lock:
            self.requests.append(r)
        return r

    def members(self, request: str | None = None, outcome: str | None = None) -> list[str]:
        with self.lock:
            return [
                r.member_id
                for r in self.requests
                if (request is None or r.request == request) and (outcome is None or r.outcome == outcome)
            ]


def _count_discards(result: Any, held: list[str], failed: int) -> None:
    if hasattr(result, "discarded_from"):
        result.parts_discarded = len(held) + failed
        result.discarded_from = held + [""] * failed


class ArsStandIn:
    """One ARS's action servers and GroundCommand service (see module docstring)."""

    def __init__(self, node: Node, ars: str, recorder: Recorder, group: ReentrantCallbackGroup) -> None:
        from sensor_msgs.msg import JointState
        from tlt_interfaces.action import AddCrossFrame, AddMember, AffixMember, FoundationRivet
        from tlt_interfaces.msg import EndEffectorState
        from tlt_interfaces.srv import GroundCommand, InspectPart, SetBlackboardValue

        from tlt_ars.config import default_config_path, load_ars_config
        from tlt_ars.ground_writes import load_ground_writes

        self.node, self.ars, self.recorder = node, ars, recorder
        self.hold_s = 0.0  # how long each request takes
        self.present_after_s = 0.0  # how long the ARS works before it presents the part
        self.fail: dict[str, str] = {}  # member id -> reason to fail with
        # (request, member id) -> the JointCheck fields of each successive result's joints (the
        # last repeats): how the ARS found the joints it shot.
        self.joints: dict[tuple[str, str], list[list[dict[str, Any]]]] = {}
        self.present_parts = True
        self.call_timeout_s = 5.0  # an inspection call unanswered this long is given up, the part shown again
        self.max_parts = 3
        # A part an earlier request left in the gripper, from this dispenser: the next AddMember or
        # AddCrossFrame discards it first and names its dispenser in the result.
        self.held_from: str | None = None
        self.paused = threading.Event()
        self.commands: list[int] = []
        self.inspect = node.create_client(InspectPart, ros_names.CRS_INSPECT_PART, callback_group=group)
        self.servers = []
        for request, kind in (
            ("add_cross_frame", AddCrossFrame),
            ("add_member", AddMember),
            ("affix_member", AffixMember),
            ("foundation_rivet", FoundationRivet),
        ):
            self.servers.append(
                ActionServer(
                    node,
                    kind,
                    ros_names.ars_action(ars, request),
                    execute_callback=lambda handle, request=request, kind=kind: self._execute(
                        handle, request, kind
                    ),
                    goal_callback=lambda goal: GoalResponse.ACCEPT,
                    cancel_callback=lambda handle: CancelResponse.ACCEPT,
                    callback_group=group,
                )
            )
        self.service = node.create_service(
            GroundCommand, ros_names.ground_command_service(ars), self._on_command, callback_group=group
        )
        self.config = load_ars_config(default_config_path(ars))
        self.ground_writes = load_ground_writes(self.config.raw, self.config.writable_blackboard_path)
        self.bb_service = node.create_service(
            SetBlackboardValue,
            ros_names.set_blackboard_service(ars),
            self.ground_writes.on_request,
            callback_group=group,
        )
        self.ee_calibrated = True  # what its end effector's driver says of the width joint
        self._ee_pub = node.create_publisher(EndEffectorState, ros_names.state_topic(ros_names.ee(ars)), 10)
        self._arm_pub = node.create_publisher(JointState, ros_names.joint_states_topic(ros_names.ur(ars)), 10)
        self._hardware_timer = node.create_timer(0.1, self._publish_hardware, callback_group=group)

    def _publish_hardware(self) -> None:
        """The states of the ARS's end effector and arm drivers, which the CRS's Start checks."""
        ee, ur = ros_names.ee(self.ars), ros_names.ur(self.ars)
        self._ee_pub.publish(
            self._ee_pub.msg_type(
                ars=self.ars,
                joint_names=[f"{ee}_grasp_left", f"{ee}_grasp_right", f"{ee}_width"],
                position=[0.0, 0.0, 0.1],
                velocity=[0.0] * 3,
                effort=[0.0] * 3,
                calibrated=self.ee_calibrated,
            )
        )
        joints = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
        names = [f"{ur}_{j}_joint" for j in joints]
        self._arm_pub.publish(self._arm_pub.msg_type(name=names, position=[0.0] * 6))

    def _on_command(self, request: Any, response: Any) -> Any:
        self.commands.append(request.command)
        if request.command == 2:
            self.paused.set()
        elif request.command in (0, 3):
            self.paused.clear()
        response.accepted = True
        return response

    def _execute(self, handle: Any, request: str, kind: Any) -> Any:
        goal = handle.request
        member = getattr(goal, "member_id", "") or getattr(goal, "joint_id", "")
        joint = getattr(goal, "joint", "")
        record = self.recorder.add(Request(self.ars, request, member, time.monotonic(), joint=joint))
        result = kind.Result()
        discarded = 0  # parts failed at inspection, of the member's dispenser, which is not named
        held = []
        if request in ("add_cross_frame", "add_member") and self.held_from:
            held, self.held_from = [self.held_from], None
        feedback = kind.Feedback(step="working", progress=0.5)
        handle.publish_feedback(feedback)
        if request in ("add_cross_frame", "add_member") and self.present_parts:
            from tlt_interfaces.srv import InspectPart

            deadline = time.monotonic() + self.present_after_s
            while time.monotonic() < deadline and not CLOSING.is_set() and not handle.is_cancel_requested:
                time.sleep(0.01)
            passed = False
            while discarded < self.max_parts:
                if not handle.is_active or handle.is_cancel_requested or CLOSING.is_set():
                    break
                camera = INSPECTION_CAMERA[self.ars]
                call = InspectPart.Request(member_id=member, part_kind="part", camera=camera)
                if not self.inspect.wait_for_service(timeout_sec=2.0):
                    break
                report = self.inspect.call(call, timeout_sec=self.call_timeout_s)
                if report is not None and report.report.passed:
                    passed = True
                    break
                if report is None or report.report.not_inspected or report.report.cannot_judge:
                    time.sleep(0.1)  # not judged: the real ARS keeps the part and presents it again
                    continue
                discarded += 1
            if not passed:
                result.success, result.reason = False, f"no part passed inspection ({discarded} discarded)"
                _count_discards(result, held, discarded)
                record.outcome = "failed"
                handle.abort() if not handle.is_cancel_requested else handle.canceled()
                return result
        deadline = time.monotonic() + self.hold_s
        while (time.monotonic() < deadline or self.paused.is_set()) and not CLOSING.is_set():
            if handle.is_cancel_requested:
                record.outcome = "canceled"
                handle.canceled()
                return result
            time.sleep(0.01)
        _count_discards(result, held, discarded)
        if member in self.fail:
            result.success, result.reason = False, self.fail[member]
            record.outcome = "failed"
            handle.succeed()
            return result
        result.success = True
        result_joints = self.joints.get((request, member))
        if result_joints:
            from tlt_interfaces.msg import JointCheck

            fields = result_joints.pop(0) if len(result_joints) > 1 else result_joints[0]
            result.joints = [JointCheck(member_id=member, **f) for f in fields]
        record.outcome = "succeeded"
        handle.succeed()
        return result

    def destroy(self) -> None:
        for server in self.servers:
            server.destroy()
        self.node.destroy_service(self.service)
        self.node.destroy_service(self.bb_service)
        self.node.destroy_timer(self._hardware_timer)


# The lifter ZED each ARS presents its parts to (config/ars/ars_*.yaml cameras.inspection).
INSPECTION_CAMERA = {"ars_x": "zed_right", "ars_y": "zed_left"}


class VisionStandIn:
    """Vision's inspection services, the ones the CRS calls."""

    CANNOT_JUDGE = "cannot judge"  # a verdict of ``part_verdicts``: no verdict, the part is kept

    def __init__(self, node: Node, group: ReentrantCallbackGroup) -> None:
        # member id -> verdicts of successive looks: True, False, or CANNOT_JUDGE (no verdict)
        self.part_verdicts: dict[str, list[bool | str]] = {}
        self.bay_passes = True
        self.part_calls: list[str] = []
        self.part_cameras: list[str] = []
        self.part_delay_s = 0.0  # how long a part inspection takes
        self.bay_calls: list[int] = []
        self.cameras: CameraStandIn | None = None  # the mounts, read when the bay is inspected
        self.mounts_at_bay_calls: list[tuple[list[float], list[float]]] = []
        self._node, self._group = node, group
        self._services: list[Any] = []
        self.readiness = ReadinessPublisher(node, ros_names.VISION_STATUS, "vision")
        self.serve()

    def serve(self) -> None:
        """Offer the services, and say ready (as vision does once it has heard every joint state)."""
        from tlt_interfaces.srv import InspectBay, InspectPart

        self.readiness.say("")
        self._services = [
            self._node.create_service(srv_type, name, handler, callback_group=self._group)
            for srv_type, name, handler in (
                (InspectPart, ros_names.VISION_INSPECT_PART, self._part),
                (InspectBay, ros_names.VISION_INSPECT_BAY, self._bay),
            )
        ]

    def withdraw(self) -> None:
        """As if the vision node were not up yet."""
        for service in self._services:
            self._node.destroy_service(service)
        self._services = []

    def _part(self, request: Any, response: Any) -> Any:
        self.part_calls.append(request.member_id)
        self.part_cameras.append(request.camera)
        verdicts = self.part_verdicts.get(request.member_id, [])
        verdict = verdicts.pop(0) if verdicts else True
        passed = verdict is True
        time.sleep(self.part_delay_s)
        response.report.target_id = request.member_id
        response.report.passed = passed
        response.report.cannot_judge = verdict == self.CANNOT_JUDGE
        response.report.reasons = (
            []
            if passed
            else ["cannot judge the end fitting: depth too noisy to certify"]
            if verdict == self.CANNOT_JUDGE
            else ["strut_tube chamfer 0.02 m above threshold"]
        )
        return response

    def _bay(self, request: Any, response: Any) -> Any:
        self.bay_calls.append(request.bay)
        if self.cameras is not None:
            self.mounts_at_bay_calls.append(self.cameras.reading())
        response.report.target_id = f"bay{request.bay}"
        response.report.passed = self.bay_passes
        response.report.reasons = [] if self.bay_passes else ["corner x0_y0 misaligned"]
        return response


class _Trajectories:
    """A FollowJointTrajectory server that jumps to the last point after ``time_scale`` x its duration."""

    def __init__(
        self, node: Node, action: str, apply: Callable[[list[str], list[float]], None], group: Any
    ) -> None:
        from tlt_interfaces.action import FollowJointTrajectory

        self.kind = FollowJointTrajectory
        self.apply = apply
        self.time_scale = 0.002
        self.goals: list[list[float]] = []
        self.canceled = 0
        self.server = ActionServer(
            node,
            FollowJointTrajectory,
            action,
            execute_callback=self._execute,
            cancel_callback=lambda handle: CancelResponse.ACCEPT,
            callback_group=group,
        )

    def _execute(self, handle: Any) -> Any:
        trajectory = handle.request.trajectory
        point = trajectory.points[-1]
        self.goals.append(list(point.positions))
        duration = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
        deadline = time.monotonic() + duration * self.time_scale
        while time.monotonic() < deadline and not CLOSING.is_set():
            if handle.is_cancel_requested:
                self.canceled += 1
                handle.canceled()
                return self.kind.Result(error_code=-4, error_string="canceled")
            time.sleep(0.005)
        self.apply(list(trajectory.joint_names), list(point.positions))
        handle.succeed()
        return self.kind.Result(error_code=0)


class LifterStandIn:
    def __init__(self, node: Node, group: Any, joints: tuple[str, ...]) -> None:
        from tlt_interfaces.msg import LifterState
        from tlt_interfaces.srv import SetLifterMode

        self.msg_type = LifterState
        self.state = 1  # HARDWARE_CONTROL
        self.positions = [0.1] * 4  # the build position (crs.yaml lifter.lowered_m)
        self.joints = list(joints)
        self.mode_calls: list[int] = []
        self.publishing = True
        self.link_ok = True  # what the driver says of its link to the firmware
        self.pub = node.create_publisher(LifterState, ros_names.state_topic(ros_names.LIFTER), 10)
        node.create_service(SetLifterMode, ros_names.LIFTER_SET_MODE, self._mode, callback_group=group)
        self.trajectories = _Trajectories(
            node, ros_names.trajectory_action(ros_names.LIFTER), self._apply, group
        )
        node.create_timer(0.02, self.publish, callback_group=group)

    def _apply(self, names: list[str], positions: list[float]) -> None:
        if self.state != 2:
            return  # the firmware moves only in CRS Control
        for name, p in zip(names, positions, strict=True):
            self.positions[self.joints.index(name)] = p

    def _mode(self, request: Any, response: Any) -> Any:
        self.mode_calls.append(request.mode)
        self.state = request.mode
        response.success, response.state = True, self.state
        return response

    def publish(self) -> None:
        if not self.publishing:
            return
        msg = self.msg_type()
        msg.state = self.state
        msg.joint_names = self.joints
        msg.encoder_positions = [float(p) for p in self.positions]
        msg.encoder_counts = [int(p * 200000) for p in self.positions]
        msg.link_ok = self.link_ok
        msg.fault = "" if self.link_ok else "firmware does not answer"
        self.pub.publish(msg)


class GripperStandIn:
    def __init__(
        self, node: Node, group: Any, component: str, joints: tuple[str, ...], threshold: float
    ) -> None:
        from std_msgs.msg import Float64MultiArray
        from tlt_interfaces.msg import GripperState

        self.msg_type = GripperState
        self.component = component
        self.joints = list(joints)
        self.threshold = threshold
        self.positions = [0.0] * len(joints)
        self.commands: list[list[float]] = []
        self.pub = node.create_publisher(GripperState, ros_names.state_topic(component), 10)
        if component == ros_names.TOP_GRIPPERS:
            node.create_subscription(
                Float64MultiArray,
                ros_names.position_command_topic(component),
                self._command,
                10,
                callback_group=group,
            )
            self.trajectories = None
        else:
            self.trajectories = _Trajectories(
                node, ros_names.trajectory_action(component), self._apply, group
            )
        node.create_timer(0.02, self.publish, callback_group=group)

    def _command(self, msg: Any) -> None:
        self.commands.append(list(msg.data))
        self.positions = list(msg.data)

    def _apply(self, names: list[str], positions: list[float]) -> None:
        self.commands.append(positions)
        for name, p in zip(names, positions, strict=True):
            self.positions[self.joints.index(name)] = p

    def set_engaged(self, engaged: bool) -> None:
        self.positions = [self.threshold * (1.2 if engaged else 0.0)] * len(self.joints)

    @property
    def engaged(self) -> list[bool]:
        return [p >= self.threshold for p in self.positions]

    def publish(self) -> None:
        msg = self.msg_type()
        msg.group = self.component
        msg.joint_names = self.joints
        msg.position = [float(p) for p in self.positions]
        msg.engaged = self.engaged
        self.pub.publish(msg)


class CameraStandIn:
    """The camera mounts: a trajectory server, and joint states at 50 Hz that trail its end by
    ``trail_s`` (servos behind their controller), moving at a constant speed to the goal."""

    JOINTS = ("camera_mount_1", "camera_mount_2")

    def __init__(self, node: Node, group: Any) -> None:
        from sensor_msgs.msg import JointState

        self.JointState = JointState
        self.positions: list[float] = [0.0, 0.0]  # the goal of the last trajectory
        self.trail_s = 0.3
        self._from, self._since = [0.0, 0.0], -math.inf
        self.trajectories = _Trajectories(
            node, ros_names.trajectory_action(ros_names.CAMERA_MOUNTS), self._apply, group
        )
        topic = ros_names.joint_states_topic(ros_names.CAMERA_MOUNTS)
        self._pub = node.create_publisher(JointState, topic, 10)
        self._clock = node.get_clock()
        node.create_timer(0.02, self._publish, callback_group=group)

    def _apply(self, names: list[str], positions: list[float]) -> None:
        self._from, self._since = self.reading()[0], time.monotonic()
        self.positions = positions

    def reading(self) -> tuple[list[float], list[float]]:
        """Where the mounts stand now and their speeds."""
        f = min(1.0, (time.monotonic() - self._since) / self.trail_s)
        pairs = list(zip(self._from, self.positions, strict=True))
        at = [a + f * (b - a) for a, b in pairs]
        speed = [0.0 if f >= 1.0 else (b - a) / self.trail_s for a, b in pairs]
        return at, speed

    def _publish(self) -> None:
        at, speed = self.reading()
        msg = self.JointState(name=list(self.JOINTS), position=at, velocity=speed)
        msg.header.stamp = self._clock.now().to_msg()
        self._pub.publish(msg)


class Rig:
    """Every stand-in on one node, spun (with any other node added) in a background executor."""

    def __init__(self, with_drivers: bool = True, with_ars: bool = True) -> None:
        from tlt_crs.config import CrsConfig

        defaults = CrsConfig(mission=ONE_BAY, state_file=Path("unused"), progress_file=Path("unused"))
        self.node = rclpy.create_node("crs_test_rig")
        self.group = ReentrantCallbackGroup()
        self.recorder = Recorder()
        self.ars: dict[str, ArsStandIn] = {}
        if with_ars:
            for name in ros_names.ARS_AGENTS:
                self.ars[name] = ArsStandIn(self.node, name, self.recorder, self.group)
        self.vision = VisionStandIn(self.node, self.group)
        if with_drivers:
            self.lifter = LifterStandIn(self.node, self.group, defaults.lifter.joints)
            self.top = GripperStandIn(
                self.node, self.group, ros_names.TOP_GRIPPERS, defaults.top_grippers.joints, 0.022
            )
            self.active = GripperStandIn(
                self.node, self.group, ros_names.ACTIVE_GRIPPERS, defaults.active_grippers.joints, 1.2
            )
            self.cameras = CameraStandIn(self.node, self.group)
            self.vision.cameras = self.cameras
            self.top.set_engaged(True)  # a bay starts with the Top Grippers holding the tower
        self.nodes: list[Node] = []
        self.executor = MultiThreadedExecutor(num_threads=8)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not CLOSING.is_set() and rclpy.ok():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except InvalidHandle:
                # A stand-in withdrawn (VisionStandIn.withdraw) while the wait set was built: the
                # next wait is clean. Stopping here would leave every callback of the rig unserved.
                continue
            except Exception as error:
                if CLOSING.is_set() or not rclpy.ok():
                    return
                # A stand-in callback that raised (future.result() re-raises it here). Stopping would
                # leave the rig deaf, and the test would fail later on a timeout naming something else.
                print(f"crs test rig: a callback raised {error!r}; spinning on", flush=True)

    def add(self, node: Node) -> None:
        self.executor.add_node(node)
        self.nodes.append(node)

    def close(self) -> None:
        CLOSING.set()
        try:
            self._thread.join(timeout=5.0)
            stop_executor(self.executor, 5.0)
            # Destroyed explicitly: a node left to the garbage collector keeps its DDS participant
            # alive after rclpy.shutdown, and later tests' cross-process actions then went unanswered.
            # So does an action server or client left by Node.destroy_node (the stand-in ARS X
            # servers of one test were still listed in the next, which found ARS X there).
            for node in [*self.nodes, self.node]:
                destroy_node(node)
            with warnings.catch_warnings():
                # A goal a stand-in ARS accepted as the test ended: its execute coroutine, queued on
                # this executor, never ran. Dropped here, not when pytest lets go of the rig.
                warnings.filterwarnings("ignore", NEVER_AWAITED, RuntimeWarning)
                self.executor = None
                gc.collect()
        finally:
            CLOSING.clear()


@pytest.fixture
def ros():
    rclpy.init()
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()
    rclpy.try_shutdown()
    with warnings.catch_warnings():
        # A goal a test's own action server accepted as the test ended: its execute coroutine was
        # queued on an executor that shut down first (the rig drops its own in Rig.close).
        warnings.filterwarnings("ignore", NEVER_AWAITED, RuntimeWarning)
        gc.collect()  # drop the context's participant now, not whenever the collector gets to it


@pytest.fixture
def rig(ros):
    r = Rig()
    yield r
    r.close()


def fast_config(tmp_path: Path, mission: Path = ONE_BAY, **timeouts: float):
    """A CRS configuration with short timeouts and state files under ``tmp_path``."""
    from tlt_crs.config import CrsConfig, Timeouts

    values = dict(
        # Each test's context is a new node: finding the stand-ins' servers is a fresh discovery,
        # which takes seconds on a loaded machine. Tests of these timeouts set their own.
        ars_server_s=5.0,
        service_s=5.0,
        # Not short: on CI's two busy cores the stand-in's answer has taken longer than 3 s to arrive.
        vision_s=10.0,
        actuator_s=5.0,
        part_presented_s=5.0,
        inspect_handoff_s=5.0,
        forward_s=1.0,
        # The stand-in drivers publish every 20 ms, but a busy machine can hold a message up for
        # more than half a second; an older state than this still means the driver went silent.
        sensor_max_age_s=1.5,
    )
    values.update(timeouts)
    return CrsConfig(
        mission=mission,
        state_file=tmp_path / "tower.json",
        progress_file=tmp_path / "indexed.json",
        writable_blackboard=REGISTRY,
        tick_rate_hz=50.0,
        timeouts=Timeouts(**values),
    )


def make_context(rig: Rig, config: Any, clock: Callable[[], float] | None = None):
    """A CRS context on its own node (spun by the rig's executor), with its model and registry."""
    from tlt_common.bt.writable_blackboard import WritableBlackboard
    from tlt_common.mission.schema import load_mission
    from tlt_common.mission.tower_model import TowerModel
    from tlt_crs.behaviours.inspection import serve_inspect_part
    from tlt_crs.context import CrsContext
    from tlt_crs.index_record import IndexRecord

    mission = load_mission(config.mission)
    model = TowerModel.open(mission, config.state_file)
    registry = WritableBlackboard.load(config.writable_blackboard)
    registry.initialise_defaults()
    node = rclpy.create_node("crs_under_test")
    rig.add(node)
    ctx = CrsContext(node, config, mission, model, registry, index=IndexRecord(mission, config.progress_file))
    serve_inspect_part(ctx)
    return ctx


def tick_until(
    root: py_trees.behaviour.Behaviour,
    timeout: float = 10.0,
    until: Callable[[], bool] | None = None,
    period: float = 0.005,
) -> Status:
    """Tick ``root`` in this thread (the executor spins in another, as in the CRS node) until it
    finishes, or ``until()`` holds; fail the test after ``timeout`` s."""
    from tlt_common.bt.viewer import render_text

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for _ in root.tick():
            pass
        finished = until() if until is not None else root.status in (Status.SUCCESS, Status.FAILURE)
        if finished:
            if root.status == Status.FAILURE:  # shown by pytest when the test fails
                print(render_text(root, collapse_invalid=True))
            return root.status
        time.sleep(period)
    raise AssertionError(f"not done after {timeout} s:\n{render_text(root, collapse_invalid=True)}")


def wait_for(predicate: Callable[[], bool], timeout: float = 5.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.01)
    raise AssertionError(f"{what} not reached within {timeout} s")


@pytest.fixture
def crs():
    """The helpers of this file, for the tests (importlib mode cannot import a conftest)."""
    import types

    return types.SimpleNamespace(
        ONE_BAY=ONE_BAY,
        TWO_BAY=TWO_BAY,
        REGISTRY=REGISTRY,
        REPO=REPO,
        fast_config=fast_config,
        make_context=make_context,
        tick_until=tick_until,
        wait_for=wait_for,
        Rig=Rig,
        ArsStandIn=ArsStandIn,
    )
