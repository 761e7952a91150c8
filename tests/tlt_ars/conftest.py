"""An ARS on the real hardware path, for the ARS tests.

* The arm: the emulated UR controller (its own process, real RTDE bytes) and the UR driver node
  in this process (real ur-rtde), on a loopback address of its own.
* The end effector: an emulated Dynamixel chain on a pseudo-terminal and the EE driver node
  (real dynamixel-sdk), with a GPIO whose limit switch follows the width servo and whose outputs
  are recorded.
* :class:`World`: ground truth standing in for the twin. It watches the arm (forward kinematics
  of the emulated joints) and the jaws: jaws opening at a dispenser's top part put a part between
  them (the emulated grasp servos then stop on it and press, which is what ``part_grasped`` reads);
  jaws opening anywhere else let the part go where it is. The gun passing a rivet pick loads a
  rivet; firing spends it.
* The ARS keeps its state file in a directory of the stack's own; :meth:`Stack.restart_ars`
  replaces the ARS by a new one on the same files, as the launcher restarts a dead process.
* Vision and CRS stand-ins answering LocateTag, CheckAlignment and InspectPart (rivet) from that
  ground truth, and the CRS's InspectPart with a scripted list of verdicts (the issue allows
  answering vision from ground truth until vision lands).
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Collection, Iterator
from pathlib import Path

import numpy as np
import pytest
import rclpy
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import Pose
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from tlt_interfaces.action import AddCrossFrame, AddMember, AffixMember, FoundationRivet
from tlt_interfaces.msg import DispenserState, EndEffectorState, MemberState, MissionProgress
from tlt_interfaces.srv import CheckAlignment, GroundCommand, InspectPart, LocateTag
from tlt_sim.emulators.dynamixel_chain import DynamixelChain
from tlt_sim.emulators.ur_controller_config import URControllerConfig
from tlt_sim.emulators.ur_controller_process import URControllerProcess

from tlt_ars.config import ars_config_from_dict, default_config_path
from tlt_ars.node import ArsNode
from tlt_ars.planning.targets import dispenser_targets, part_in_tool, placement_targets
from tlt_ars.planning.world import dispenser_frame
from tlt_common import ros_names
from tlt_common.config_schema import load_yaml
from tlt_common.geometry.transforms import pose_error
from tlt_common.ros.action_client import SerialisedActionClient
from tlt_common.ros.executor_stop import stop_executor
from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.spin_loop import spin
from tlt_drivers.dynamixel.config import validate_chain
from tlt_drivers.nodes.ee import EndEffectorNode
from tlt_drivers.ur.config import CONFIG_DIR as UR_CONFIG_DIR
from tlt_drivers.ur.config import load_ur_config
from tlt_drivers.ur.node import URNode

HOST = "127.0.0.61"  # a loopback address no other test suite's emulated arm uses
RTDE_HZ = 125.0
TICKS_PER_RAD = 4096 / (2 * math.pi)
GRASP_STOP_RAD = 0.7  # where the jaws stop on a part
OPEN_BELOW_RAD = 0.3
NEAR_M = 0.03
WAIT_S = 60.0
ACTIONS = {
    "add_cross_frame": AddCrossFrame,
    "add_member": AddMember,
    "affix_member": AffixMember,
    "foundation_rivet": FoundationRivet,
}


def ars_test_config(**overrides) -> dict:
    """The shipped ars_x file with the test mission, full speed and short timeouts."""
    raw = load_yaml(default_config_path("ars_x"))
    raw["mission"] = "missions/two_bay.yaml"
    raw["check_reach"] = False
    raw["arm"]["velocity_scale"] = 1.0
    # In this process the driver's control cycle shares two busy cores with the ARS, the EE, the
    # stand-ins and whatever else runs: how far the arm trails the commanded path depends on the
    # machine's load, so these tests judge where motions end, not how closely they are tracked.
    raw["arm"]["path_tolerance"] = -1.0
    raw["arm"]["goal_time_tolerance_s"] = 5.0
    raw["end_effector"]["width"] = {"cross_frame": 0.0, "vertical": 0.0, "diagonal": 0.02, "rivet": 0.0}
    raw["end_effector"]["grasp_time_s"] = 0.4
    raw["end_effector"]["fire_s"] = 0.1
    # A motion's result may come seconds late when the two cores are busy: the margin is wide.
    raw["timeouts"].update(width_s=10.0, service_s=5.0, stop_s=3.0, sensor_s=2.0, trajectory_margin_s=20.0)
    for key, value in overrides.items():
        raw[key] = value
    return raw


def ee_test_config(port: str) -> dict:
    joint = {"mode": "current_based_position", "goal_current_ma": 1000.0, "controller": "trajectory",
             "unit": "rad", "lower": -0.2, "upper": 1.4, "max_velocity": 4.0}  # fmt: skip
    return validate_chain(
        {
            "component": "ee_x",
            "port": port,
            "rate_hz": 100.0,
            "state_rate_hz": 20.0,
            # Generous link timing: other work shares the two cores with the emulated chain.
            "comm": {"latency_timer_ms": 200.0, "retries_per_transfer": 5},
            "trajectory": {"path_tolerance": -1.0, "goal_tolerance": 0.02, "goal_time_tolerance_s": 3.0},
            "joints": [
                {"name": "ee_x_grasp_left", "id": 1, **joint},
                {"name": "ee_x_grasp_right", "id": 2, **joint},
                {
                    "name": "ee_x_width",
                    "id": 3,
                    "mode": "extended_position",
                    "controller": "group_position",
                    "unit": "m",
                    "lead_m_per_rev": 0.01,
                    "zero_ticks": 0,
                    "lower": 0.0,
                    "upper": 0.05,
                    "max_velocity": 0.05,
                },
            ],
            "ee": {
                "ars": "ars_x",
                "width_joint": "ee_x_width",
                "grasp_joints": ["ee_x_grasp_left", "ee_x_grasp_right"],
                "limit_switch_input": "limit_switch",
                "rivet_gun_outputs": ["rivet_gun_left", "rivet_gun_right"],
                "grasp_effort_threshold": 0.15,
                "calibration": {
                    "direction": -1,
                    "speed": 0.01,
                    "switch_position": 0.0,
                    "max_travel": 0.02,
                    "timeout_s": 10.0,
                    "on_start": True,
                },
            },
        }
    )


# A verdict of ``inspection_verdicts``: vision could not judge the part (InspectionReport.cannot_judge).
CANNOT_JUDGE = "cannot judge"


class Gpio:
    """The EE's GPIO: the limit switch closes when the width servo is at or below its zero."""

    def __init__(self, chain: DynamixelChain, switch_ticks: float) -> None:
        self.chain, self.switch_ticks = chain, switch_ticks
        self.outputs: dict[str, bool] = {}
        self.fired: list[str] = []
        self.failing_offs = 0  # this many next writes of 'off' fail, as a stuck output would

    def read_input(self, name: str) -> bool:
        return self.chain.servo(3).position <= self.switch_ticks

    def write_output(self, name: str, value: bool) -> None:
        if not value and self.failing_offs > 0:
            self.failing_offs -= 1
            raise OSError(f"{name} did not switch off (the test's stuck output)")
        if value and not self.outputs.get(name):
            self.fired.append(name)
        self.outputs[name] = value


class World:
    """Ground truth of parts, jaws and rivets; see the module docstring."""

    def __init__(self, stack: Stack) -> None:
        self.stack = stack
        self.lock = threading.Lock()
        self.remaining = {n: d.count for n, d in stack.mission.dispensers.items()}
        self.held: str | None = None  # dispenser the held part came from
        self.part_pose: np.ndarray | None = None  # where the last released part lies
        self.rivet_loaded = False
        self.grasp_offset = np.zeros(3)  # the held part sits this far (world) from the grasp centre
        self._gun_on = False
        self._source: str | None = None
        self._pick_cache: dict[tuple[str, int], list[np.ndarray]] = {}
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def tool(self) -> np.ndarray:
        q = self.stack.ur.hw.positions
        return self.stack.scene.kinematics("ars_x").forward([q[n] for n in self.stack.joint_names])

    def _picks(self, name: str) -> list[np.ndarray]:
        key = (name, self.remaining[name])
        if key not in self._pick_cache:
            targets = dispenser_targets(self.stack.scene, self.stack.mission, name, "ars_x", remaining=key[1])
            self._pick_cache[key] = [t.pose[:3, 3] for t in targets]
        return self._pick_cache[key]

    def _near(self, tool: np.ndarray, kind: str) -> str | None:
        for name, disp in self.stack.mission.dispensers.items():
            if (disp.part_kind == "rivet") != (kind == "rivet") or self.remaining[name] <= 0:
                continue
            if any(np.linalg.norm(p - tool[:3, 3]) < NEAR_M for p in self._picks(name)):
                return name
        return None

    def _run(self) -> None:
        while not self._stop.wait(0.04):
            try:
                self.step()
            except Exception:  # the driver may be between states; the next step sees it again
                continue

    def step(self) -> None:
        chain = self.stack.chain
        jaw = (chain.servo(1).position - 2048) / TICKS_PER_RAD
        tool = self.tool()
        with self.lock:
            if self._near(tool, "rivet") and not self._gun_on:
                self.rivet_loaded = True
            gun = bool(self.stack.gpio.outputs.get("rivet_gun_left"))
            if gun and not self._gun_on:
                self.rivet_loaded = False
            self._gun_on = gun
            if jaw < OPEN_BELOW_RAD:
                if self.held is not None:
                    self.part_pose = tool.copy()  # let go: the part stays where it was
                    self.part_pose[:3, 3] += self.grasp_offset
                    self.grasp_offset = np.zeros(3)
                    self.held = None
                source = self._near(tool, "part")
                for dxl in (1, 2):
                    chain.servo(dxl).set_obstacle(
                        upper=2048 + GRASP_STOP_RAD * TICKS_PER_RAD if source else None
                    )
                self._source = source
            elif self.held is None and self._source and jaw > GRASP_STOP_RAD - 0.1:
                self.held = self._source
                self.remaining[self._source] -= 1
                self._source = None

    def measured_part(self) -> np.ndarray:
        with self.lock:
            if self.held:
                pose = self.tool()
                pose[:3, 3] += self.grasp_offset
                return pose
            if self.part_pose is None:
                raise RuntimeError("no part to measure")
            return self.part_pose.copy()

    def start(self) -> None:
        self.thread.start()

    def close(self) -> None:
        self._stop.set()
        self.thread.join(timeout=2)


def pose_msg(m: np.ndarray) -> Pose:
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in m[:3, 3])
    r = m[:3, :3]
    w = math.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    if w > 1e-6:
        x, y, z = (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)
    else:  # a half turn: take the largest diagonal
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = math.sqrt(max(0.0, 1 + r[i, i] - r[j, j] - r[k, k])) * 2
        q = [0.0, 0.0, 0.0]
        q[i] = s / 4
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
        w = (r[k, j] - r[j, k]) / s
        x, y, z = q
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (
        float(x),
        float(y),
        float(z),
        float(w),
    )
    return p


class Stack:
    """The whole ARS test set-up; see the module docstring."""

    CANNOT_JUDGE = CANNOT_JUDGE

    def __init__(self) -> None:
        # RTDE at 125 Hz, as the twin streams it (a CB3's rate): the driver's own tests run the
        # e-Series' 500 Hz; here the quarter rate leaves CPU to the other test workers.
        self.emulator = URControllerProcess(
            URControllerConfig(host=HOST, unlock_delay_s=0.0, tick_hz=RTDE_HZ)
        ).start()
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        ur_config = dataclasses.replace(
            load_ur_config(UR_CONFIG_DIR / "ur_x.yaml"),
            host=HOST,
            rtde_frequency_hz=RTDE_HZ,
            reconnect_period_s=0.1,
            link_timeout_s=3.0,  # a loaded machine may starve the emulator for a while
            probe_timeout_s=2.0,
        )
        self.joint_names = list(ur_config.joint_names)
        self.ur = URNode(ur_config, context=self.context)
        self.chain = DynamixelChain([1, 2, 3])
        self.chain.start()
        self.gpio = Gpio(self.chain, 2048 - 0.002 / 0.01 * 4096)
        self.ee = EndEffectorNode(ee_test_config(self.chain.port), self.gpio, context=self.context)
        self.state_dir = Path(tempfile.mkdtemp(prefix="tlt-ars-test-"))
        self.ars_config = ars_config_from_dict(
            ars_test_config(state_file=str(self.state_dir / "ars_x.json")), "ars_x test config"
        )
        self.ars = ArsNode(self.ars_config, context=self.context)
        self.scene, self.mission = self.ars.ctx.scene, self.ars.ctx.mission
        self.world = World(self)
        # Next verdicts (None: not inspected; CANNOT_JUDGE: no verdict); none left: pass.
        self.inspection_verdicts: list[bool | str | None] = []
        self.misread_alignments = 0  # this many next CheckAlignment answers read the part 2 cm off
        self.inspection_gate: threading.Event | None = None  # set: the CRS stand-in answers
        self.inspections: list[str] = []
        self.handles: list = []
        self.client = Node("ars_test_crs", context=self.context)
        self.ee_states: list[EndEffectorState] = []
        # A test that wants every state adds a listener, never a subscription of its own: destroying
        # a subscription while the executor's thread builds its wait set kills that thread
        # (rclpy's InvalidHandle), and with it every callback of the ARS and the stand-ins.
        self.ee_listeners: list[Callable[[EndEffectorState], None]] = []
        self.client.create_subscription(EndEffectorState, "/ee_x/state", self._ee_state, 10)
        # Its own group: a call held at the gate must not hold up the stand-ins' other callbacks,
        # and two calls are still answered one after the other, in order.
        gated = MutuallyExclusiveCallbackGroup()
        self.client.create_service(
            InspectPart, ros_names.CRS_INSPECT_PART, self._crs_inspect, callback_group=gated
        )
        self.client.create_service(InspectPart, ros_names.VISION_INSPECT_PART, self._vision_inspect)
        self.client.create_service(LocateTag, ros_names.VISION_LOCATE_TAG, self._locate_tag)
        self.client.create_service(CheckAlignment, ros_names.VISION_CHECK_ALIGNMENT, self._check_alignment)
        self.ground = self.client.create_client(GroundCommand, ros_names.ground_command_service("ars_x"))
        self.actions = {
            k: SerialisedActionClient(self.client, t, ros_names.ars_action("ars_x", k))
            for k, t in ACTIONS.items()
        }
        # Each driver spins alone, as in its own process on the robot: the EE's serial transfers
        # (retried on a busy machine) must not hold up the arm's control cycle and joint states.
        self.drivers = []
        for driver in (self.ur, self.ee):
            self.drivers.append(SingleThreadedExecutor(context=self.context))
            self.drivers[-1].add_node(driver)
        self.executor = MultiThreadedExecutor(num_threads=4, context=self.context)
        self.executor.add_node(self.ars)
        self.executor.add_node(self.client)
        self._stop = threading.Event()
        self.threads = [
            threading.Thread(target=spin, args=(e, self.context, self._stop.is_set), daemon=True)
            for e in (*self.drivers, self.executor)
        ]
        for t in self.threads:
            t.start()
        self.wait(lambda: self.ee_states and self.ee_states[-1].calibrated, "EE calibrated")
        self.wait(lambda: self.ars.ctx.arm_q() is not None, "arm joint states at the ARS")
        self.world.start()

    def _ee_state(self, msg: EndEffectorState) -> None:
        self.ee_states.append(msg)
        del self.ee_states[:-400]
        for listener in tuple(self.ee_listeners):
            listener(msg)

    # ----- stand-ins -----
    def _crs_inspect(self, request, response):
        self.inspections.append(request.member_id)
        if self.inspection_gate is not None:
            self.inspection_gate.wait(WAIT_S)
        passed = self.inspection_verdicts.pop(0) if self.inspection_verdicts else True
        response.report.target_id, response.report.target_kind = request.member_id, request.part_kind
        if passed is None:  # the CRS did not inspect it (say, restarted and not expecting it yet)
            response.report.not_inspected = True
            response.report.reasons = ["the CRS is not expecting a part for inspection"]
            return response
        if passed == CANNOT_JUDGE:  # vision saw nothing wrong but could not settle it
            response.report.cannot_judge = True
            response.report.reasons = ["cannot judge the end fitting: depth too noisy to certify"]
            return response
        response.report.passed = passed and self.world.held is not None
        if not response.report.passed:
            response.report.reasons = [
                "end fitting cracked" if self.world.held else "no part in front of the camera"
            ]
        return response

    def _vision_inspect(self, request, response):
        response.report.target_id, response.report.target_kind = request.member_id, request.part_kind
        response.report.passed = request.part_kind == "rivet" and self.world.rivet_loaded
        if not response.report.passed:
            response.report.reasons = ["no rivet in the gun"]
        return response

    def _locate_tag(self, request, response):
        disp = self.mission.dispensers.get(request.dispenser)
        if disp is None:
            response.found, response.reason = False, "no such tag in view"
            return response
        response.found, response.tag_id = True, list(self.mission.dispensers).index(request.dispenser)
        response.pose.header.frame_id = "world"
        response.pose.pose = pose_msg(dispenser_frame(self.scene, disp))
        return response

    def _check_alignment(self, request, response):
        member = self.mission.member(request.member_id)
        try:
            part = self.world.measured_part()
        except RuntimeError as exc:
            response.aligned, response.reason = False, str(exc)
            return response
        # Vision reports the part's own frame (its middle), off the tool for a diagonal.
        part = part @ part_in_tool(self.mission, member.kind)
        errors = [
            pose_error(part, t.pose @ part_in_tool(self.mission, member.kind))
            for t in placement_targets(self.scene, self.mission, member, "ars_x")
        ]
        pos, ang = min(errors, key=lambda e: e[0] + 0.1 * e[1])  # the candidate the part is nearest
        if self.misread_alignments > 0:
            self.misread_alignments -= 1
            pos += 0.02
        response.position_error, response.angle_error = float(pos), float(ang)
        response.aligned = bool(pos <= 0.005 and ang <= 0.035)
        response.pose.header.frame_id = "world"
        response.pose.certified = True
        response.pose.pose = pose_msg(part)
        return response

    def restart_ars(self, unheard: str) -> None:
        """The ARS gone and a new one started on the same files. A MissionProgress tells it what
        the old one knew stands, but for the member ``unheard``, whose result the CRS never heard."""
        state = self.ars.ctx.state
        placed, remaining = state.placed() - {unheard}, dict(state.remaining)
        self.executor.remove_node(self.ars)
        self.ars.close()
        destroy_node(self.ars)
        self.ars = ArsNode(self.ars_config, context=self.context)
        self.executor.add_node(self.ars)
        self.tell(placed, remaining)

    def tell(self, placed: Collection[str], remaining: dict[str, int] | None = None) -> None:
        """Tell the ARS, as the CRS does with a MissionProgress, that the members ``placed`` stand
        and the dispensers hold ``remaining`` (by default what the ARS counts); wait until it knows."""
        state = self.ars.ctx.state
        progress = crs_progress(state.mission, placed, remaining or state.remaining)
        publisher = self.client.create_publisher(MissionProgress, ros_names.CRS_MISSION_PROGRESS, 10)
        try:
            self.wait(lambda: self.ars.ctx.arm_q() is not None, "arm joint states at the ARS")
            self.wait(lambda: publisher.get_subscription_count() > 0, "the ARS subscribed to progress")
            publisher.publish(progress)
            self.wait(
                lambda: (
                    set(placed) <= state.placed()
                    and all(state.remaining[d.name] == d.remaining for d in progress.dispensers)
                ),
                "the ARS told what stands",
            )
        finally:
            self.client.destroy_publisher(publisher)

    # ----- helpers -----
    @staticmethod
    def wait(predicate, what: str, timeout: float = WAIT_S):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            time.sleep(0.02)
        raise AssertionError(f"timed out waiting for {what}")

    def send(self, request: str, feedback: list | Callable | None = None, **fields):
        """Send a goal; its feedback goes into the list ``feedback``, or to the callable."""
        goal = ACTIONS[request].Goal(**fields)
        client = self.actions[request]
        self.wait(client.server_is_ready, f"{request} server")
        on_feedback = feedback if callable(feedback) else getattr(feedback, "append", None)
        future = client.send_goal_async(
            goal, feedback_callback=(lambda m: on_feedback(m.feedback)) if on_feedback else None
        )
        handle = self.wait(future.done, "goal response") and future.result()
        self.handles.append(handle)
        return handle

    def ground_command(self, command: int) -> GroundCommand.Response:
        self.wait(self.ground.service_is_ready, "ground command service")
        future = self.ground.call_async(GroundCommand.Request(command=command))
        return self.wait(future.done, "ground command reply") and future.result()

    def arm_standing_still(self, window_s: float = 0.3, atol: float = 1e-3) -> bool:
        """True once the arm moved less than ``atol`` in every joint over ``window_s``: a speed
        sample alone can be taken at the turn of a settling oscillation."""
        q = self.ars.ctx.arm_q()
        time.sleep(window_s)
        return bool(np.allclose(self.ars.ctx.arm_q(), q, atol=atol))

    def settle(self) -> None:
        """Resume and cancel whatever a failed test left paused or running, so the next test finds
        the ARS idle."""
        if self.ars.paused:
            self.ground_command(GroundCommand.Request.RESUME)
        for handle in self.handles:
            if handle.accepted and handle.status in (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING):
                handle.cancel_goal_async()
        self.handles.clear()
        self.wait(lambda: self.ars.active is None, "the ARS idle", timeout=30)

    def result(self, handle, timeout: float = WAIT_S):
        future = handle.get_result_async()
        self.wait(future.done, "goal result", timeout)
        return future.result()

    def width(self) -> float:
        state = self.ee_states[-1]
        return state.position[list(state.joint_names).index("ee_x_width")]

    def close(self) -> None:
        self.world.close()
        self._stop.set()
        for t in self.threads:
            t.join(timeout=5)
        for executor in (self.executor, *self.drivers):
            stop_executor(executor, 5.0)
        self.ars.close()
        self.ee.shutdown()
        self.ur.shutdown()
        for node in (self.ars, self.ee, self.ur, self.client):
            destroy_node(node)
        rclpy.try_shutdown(context=self.context)
        self.chain.stop()
        self.emulator.close()
        shutil.rmtree(self.state_dir, ignore_errors=True)


def crs_progress(mission, placed: Collection[str], remaining: dict[str, int]) -> MissionProgress:
    """What the CRS would say: of ``mission``, the members ``placed`` stand, and the dispensers
    hold ``remaining``."""
    kinds = {"cross_frame": 0, "vertical": 1, "diagonal": 2, "foundation_rivet": 3}
    progress = MissionProgress(mission=mission.name, current_bay=1, started=True)
    progress.members = [
        MemberState(member_id=m.id, kind=kinds[m.kind], bay=m.bay, state=MemberState.STATE_PLACED)
        for m in mission.members
        if m.id in placed
    ]
    progress.dispensers = [DispenserState(name=name, remaining=n) for name, n in remaining.items()]
    return progress


@pytest.fixture
def stack(ars_stack: Stack) -> Iterator[Stack]:
    """The module's stack, left idle after each test."""
    yield ars_stack
    if not ars_stack.ars.finished.is_set():
        ars_stack.settle()


@pytest.fixture(scope="module")
def ars_stack() -> Iterator[Stack]:
    s = Stack()
    try:
        yield s
    finally:
        s.close()


__all__ = ["Stack", "World", "ars_test_config"]
