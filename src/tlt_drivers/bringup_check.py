"""Bring-up check: exercise every driver node through its ROS interfaces and report what works.

What an engineer runs after powering up a Jetson's share of the unit (or the emulated hardware):
for each component it waits for the driver to come up, then moves each mechanism a little and
back through the same interfaces the CRS and ARS use, and checks the motion in the state that
comes back from the device. It leaves the lifter in Safe. Exit code 0 when every check passed.
A driver gets ``--startup-timeout`` (60 s) to come up, since the check starts with the drivers;
each step after that ``--timeout`` (15 s).

    tlt-bringup-check --components lifter,top_grippers,ee_x
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from tlt_interfaces.action import FollowJointTrajectory
from tlt_interfaces.msg import EndEffectorState, GripperState, HardwareStatus, LifterState
from tlt_interfaces.srv import SetActuatorState, SetLifterMode
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from tlt_common import ros_names
from tlt_common.ros.action_client import SerialisedActionClient
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.rosout_logging import forward_logging_to_rosout, init_rclpy
from tlt_common.ros.stamps import set_stamp

COMPONENTS = ("lifter", "top_grippers", "active_grippers", "camera_mounts", "ee_x", "ee_y", "ur_x", "ur_y")


class CheckFailed(Exception):
    """A check did not see what it expected; the message says what it saw."""


@dataclass
class Result:
    component: str
    check: str
    ok: bool
    detail: str
    seconds: float


class BringupCheck(LeanNode):
    """Runs the checks; ROS callbacks are served by an executor thread."""

    def __init__(self, timeout_s: float, startup_timeout_s: float) -> None:
        super().__init__("bringup_check")
        self.timeout_s = timeout_s
        self.startup_timeout_s = startup_timeout_s
        self._latest: dict[str, Any] = {}
        self._changed = threading.Condition()
        self.results: list[Result] = []
        self._kept_clients: dict[tuple[str, str], Any] = {}

    # --- plumbing -----------------------------------------------------------------------------------
    def watch(self, msg_type: type, topic: str) -> None:
        def store(msg: Any) -> None:
            with self._changed:
                self._latest[topic] = msg
                self._changed.notify_all()

        if topic not in self._latest:
            self._latest[topic] = None
            self.create_subscription(msg_type, topic, store, 10)

    def wait_for(
        self, topic: str, predicate: Callable[[Any], bool], what: str, timeout_s: float | None = None
    ):
        """The first message on ``topic`` satisfying ``predicate``; CheckFailed after the timeout."""
        deadline = time.monotonic() + (timeout_s or self.timeout_s)
        with self._changed:
            while True:
                msg = self._latest.get(topic)
                if msg is not None and predicate(msg):
                    return msg
                left = deadline - time.monotonic()
                if left <= 0:
                    raise CheckFailed(
                        f"{what}: not seen on {topic} within {timeout_s or self.timeout_s:g} s"
                        + ("" if msg is None else f" (last: {_brief(msg)})")
                    )
                self._changed.wait(left)

    # Clients are kept for the node's life: destroying one while the executor thread waits on it
    # invalidates the wait set under it.
    def _client(self, kind: str, msg_type: type, name: str) -> Any:
        key = (kind, name)
        if key not in self._kept_clients:
            self._kept_clients[key] = (
                SerialisedActionClient(self, msg_type, name)
                if kind == "action"
                else self.create_client(msg_type, name)
            )
        return self._kept_clients[key]

    def call(self, srv_type: type, name: str, request: Any) -> Any:
        client = self._client("service", srv_type, name)
        if not client.wait_for_service(timeout_sec=self.timeout_s):
            raise CheckFailed(f"service {name} not available")
        return _wait_future(client.call_async(request), self.timeout_s, f"service {name}")

    def follow(
        self, component: str, joints: list[str], start: list[float], goal: list[float], duration_s: float
    ) -> None:
        """Send a two-point FollowJointTrajectory goal and wait for success."""
        name = ros_names.trajectory_action(component)
        client = self._client("action", FollowJointTrajectory, name)
        if not client.wait_for_server(timeout_sec=self.timeout_s):
            raise CheckFailed(f"action {name} not available")
        trajectory = JointTrajectory(joint_names=joints)
        for t, positions in ((0.0, start), (duration_s, goal)):
            point = JointTrajectoryPoint(positions=[float(p) for p in positions])
            set_stamp(point.time_from_start, t)
            trajectory.points.append(point)
        handle = _wait_future(
            client.send_goal_async(FollowJointTrajectory.Goal(trajectory=trajectory)),
            self.timeout_s,
            f"{name} goal acceptance",
        )
        if not handle.accepted:
            raise CheckFailed(f"{name} rejected the goal")
        outcome = _wait_future(handle.get_result_async(), duration_s + self.timeout_s, f"{name} result")
        if outcome.result.error_code != FollowJointTrajectory.Result.SUCCESSFUL:
            raise CheckFailed(f"{name}: error {outcome.result.error_code}: {outcome.result.error_string}")

    def run_check(self, component: str, check: str, fn: Callable[[], str]) -> bool:
        start = time.monotonic()
        try:
            detail, ok = fn(), True
        except CheckFailed as exc:
            detail, ok = str(exc), False
        result = Result(component, check, ok, detail, time.monotonic() - start)
        self.results.append(result)
        print(f"  {'ok  ' if ok else 'FAIL'} {component:<16} {check:<34} {detail}", flush=True)
        return ok

    def hardware_active(self, component: str) -> str:
        """The driver's first status with its interface active and link up.

        Waits the start-up allowance, not a step's timeout: the check is started with the drivers,
        and a driver process still starting (imports, its link's handshake) on a loaded machine
        has not failed.
        """
        topic = ros_names.hardware_status_topic(component)
        self.watch(HardwareStatus, topic)
        msg = self.wait_for(
            topic,
            lambda m: m.lifecycle_state == HardwareStatus.LIFECYCLE_ACTIVE and m.link_ok,
            "hardware interface active with its link up",
            timeout_s=self.startup_timeout_s,
        )
        return f"active, {msg.errors} error(s) so far"

    # --- per component ------------------------------------------------------------------------------
    def check_lifter(self) -> None:
        topic = ros_names.state_topic(ros_names.LIFTER)
        self.watch(LifterState, topic)
        if not self.run_check("lifter", "driver up", lambda: self.hardware_active("lifter")):
            return

        def to_mode(mode: int, state: int, label: str) -> str:
            reply = self.call(SetLifterMode, ros_names.LIFTER_SET_MODE, SetLifterMode.Request(mode=mode))
            if not reply.success:
                raise CheckFailed(f"refused: {reply.reason}")
            self.wait_for(topic, lambda m: m.state == state, f"lifter in {label}")
            return f"firmware reports {label}"

        if not self.run_check(
            "lifter",
            "mode CRS Control",
            lambda: to_mode(
                SetLifterMode.Request.MODE_CRS_CONTROL, LifterState.STATE_CRS_CONTROL, "CRS Control"
            ),
        ):
            return

        def raise_and_lower() -> str:
            state = self.wait_for(topic, lambda m: True, "lifter state")
            joints, start = list(state.joint_names), list(state.encoder_positions)
            up = [p + 0.01 for p in start]
            self.follow("lifter", joints, start, up, 1.0)
            risen = self.wait_for(
                topic,
                lambda m: all(abs(a - b) < 0.002 for a, b in zip(m.encoder_positions, up, strict=True)),
                "encoders 10 mm higher",
            )
            self.follow("lifter", joints, list(risen.encoder_positions), start, 1.0)
            return "encoders followed +10 mm and back"

        self.run_check("lifter", "raise 10 mm and lower", raise_and_lower)
        self.run_check(
            "lifter",
            "mode Safe",
            lambda: to_mode(SetLifterMode.Request.MODE_SAFE, LifterState.STATE_SAFE, "Safe"),
        )

    def check_top_grippers(self) -> None:
        topic = ros_names.state_topic(ros_names.TOP_GRIPPERS)
        self.watch(GripperState, topic)
        if not self.run_check("top_grippers", "driver up", lambda: self.hardware_active("top_grippers")):
            return
        publisher = self.create_publisher(
            Float64MultiArray, ros_names.position_command_topic("top_grippers"), 10
        )

        def stroke(target: float, engaged: bool) -> str:
            state = self.wait_for(topic, lambda m: True, "gripper state")
            deadline = time.monotonic() + self.timeout_s
            # Re-sent until seen: a command topic has no acknowledgement.
            while time.monotonic() < deadline:
                publisher.publish(Float64MultiArray(data=[target] * len(state.joint_names)))
                try:
                    self.wait_for(
                        topic,
                        lambda m: all(e == engaged for e in m.engaged),
                        "engaged" if engaged else "disengaged",
                        timeout_s=0.5,
                    )
                    return f"all {len(state.joint_names)} report {'engaged' if engaged else 'disengaged'}"
                except CheckFailed:
                    continue
            raise CheckFailed(f"not all {'engaged' if engaged else 'disengaged'} after {self.timeout_s:g} s")

        if self.run_check("top_grippers", "engage", lambda: stroke(0.025, True)):
            self.run_check("top_grippers", "disengage", lambda: stroke(0.0, False))

    def check_active_grippers(self) -> None:
        topic = ros_names.state_topic(ros_names.ACTIVE_GRIPPERS)
        self.watch(GripperState, topic)
        if not self.run_check(
            "active_grippers", "driver up", lambda: self.hardware_active("active_grippers")
        ):
            return

        def move(target: float, engaged: bool) -> str:
            state = self.wait_for(topic, lambda m: True, "gripper state")
            self.follow(
                "active_grippers",
                list(state.joint_names),
                list(state.position),
                [target] * len(state.joint_names),
                1.5,
            )
            self.wait_for(
                topic, lambda m: all(e == engaged for e in m.engaged), "engaged" if engaged else "disengaged"
            )
            return f"all {len(state.joint_names)} report {'engaged' if engaged else 'disengaged'}"

        if self.run_check("active_grippers", "engage", lambda: move(1.4, True)):
            self.run_check("active_grippers", "disengage", lambda: move(0.2, False))

    def check_camera_mounts(self) -> None:
        topic = ros_names.joint_states_topic(ros_names.CAMERA_MOUNTS)
        self.watch(JointState, topic)
        if not self.run_check("camera_mounts", "driver up", lambda: self.hardware_active("camera_mounts")):
            return

        def rotate(target: float, label: str) -> str:
            state = self.wait_for(topic, lambda m: True, "joint states")
            goal = [target, -target][: len(state.name)]
            self.follow("camera_mounts", list(state.name), list(state.position), goal, 1.5)
            self.wait_for(
                topic,
                lambda m: all(abs(a - b) < 0.02 for a, b in zip(m.position, goal, strict=True)),
                f"mounts {label}",
            )
            return f"mounts at {', '.join(f'{g:+.2f}' for g in goal)} rad"

        if self.run_check("camera_mounts", "rotate inward", lambda: rotate(0.6, "inward")):
            self.run_check("camera_mounts", "rotate back", lambda: rotate(0.0, "back"))

    def check_ee(self, component: str) -> None:
        topic = ros_names.state_topic(component)
        self.watch(EndEffectorState, topic)
        if not self.run_check(component, "driver up", lambda: self.hardware_active(component)):
            return

        def calibrated() -> str:
            # The driver seeks the limit switch on its own after power-up; ask only if it has not.
            try:
                self.wait_for(topic, lambda m: m.calibrated, "calibrated", timeout_s=min(5.0, self.timeout_s))
            except CheckFailed:
                reply = self.call(Trigger, ros_names.ee_calibrate_service(component), Trigger.Request())
                if not reply.success:
                    raise CheckFailed(f"calibration refused: {reply.message}") from None
                self.wait_for(topic, lambda m: m.calibrated, "calibrated", timeout_s=3 * self.timeout_s)
            return "width joint zeroed on the limit switch"

        if not self.run_check(component, "calibrated", calibrated):
            return
        publisher = self.create_publisher(Float64MultiArray, ros_names.position_command_topic(component), 10)

        def width(target: float) -> str:
            deadline = time.monotonic() + 4 * self.timeout_s
            while time.monotonic() < deadline:
                publisher.publish(Float64MultiArray(data=[target]))
                try:
                    self.wait_for(
                        topic,
                        lambda m: abs(m.position[-1] - target) < 0.002,
                        f"width {target} m",
                        timeout_s=0.5,
                    )
                    return f"width at {target * 1000:.0f} mm"
                except CheckFailed:
                    continue
            raise CheckFailed(f"width did not reach {target} m")

        self.run_check(component, "extend width 5 mm", lambda: width(0.005))

        def grasp() -> str:
            state = self.wait_for(topic, lambda m: True, "EE state")
            joints = list(state.joint_names[:2])
            self.follow(component, joints, list(state.position[:2]), [0.8, 0.8], 2.0)
            self.follow(component, joints, [0.8, 0.8], [0.0, 0.0], 2.0)
            return "grasp joints closed and opened"

        self.run_check(component, "grasp joints", grasp)

        def rivet_gun() -> str:
            for level in ("on", "off"):
                reply = self.call(
                    SetActuatorState,
                    ros_names.ee_rivet_gun_service(component),
                    SetActuatorState.Request(actuator="rivet_gun_0", state=level),
                )
                if not reply.accepted:
                    raise CheckFailed(f"rivet gun {level} refused: {reply.reason}")

                def gun_output_is(m: EndEffectorState, on: bool = level == "on") -> bool:
                    return m.rivet_gun_output[0] == on

                self.wait_for(topic, gun_output_is, f"rivet gun output {level}")
            return "GPIO output pulsed on and off"

        self.run_check(component, "rivet gun output", rivet_gun)

    def check_ur(self, component: str) -> None:
        topic = ros_names.joint_states_topic(component)
        self.watch(JointState, topic)
        if not self.run_check(component, "driver up", lambda: self.hardware_active(component)):
            return

        def wrist() -> str:
            state = self.wait_for(topic, lambda m: len(m.position) == 6, "joint states")
            start = list(state.position)
            goal = [*start[:5], start[5] + 0.2]
            self.follow(component, list(state.name), start, goal, 1.0)
            self.wait_for(topic, lambda m: abs(m.position[5] - goal[5]) < 0.01, "wrist 3 turned")
            self.follow(component, list(state.name), goal, start, 1.0)
            return "wrist 3 turned 0.2 rad and back"

        self.run_check(component, "move wrist 3", wrist)


def _spin(executor: MultiThreadedExecutor) -> None:
    try:
        executor.spin()
    except ExternalShutdownException:
        pass


def _wait_future(future: Any, timeout_s: float, what: str) -> Any:
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout_s):
        raise CheckFailed(f"{what}: no answer within {timeout_s:g} s")
    return future.result()


def _brief(msg: Any) -> str:
    text = str(msg)
    return text if len(text) < 160 else text[:157] + "..."


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="tlt-bringup-check", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--components", default=",".join(COMPONENTS), help=f"comma-separated, from {', '.join(COMPONENTS)}"
    )
    parser.add_argument("--timeout", type=float, default=15.0, help="seconds to wait for each step")
    parser.add_argument(
        "--startup-timeout",
        type=float,
        default=60.0,
        help="seconds to wait for each driver to come up (active, its link up)",
    )
    args = parser.parse_args(rclpy.utilities.remove_ros_args(["prog", *argv])[1:])
    components = [c for c in args.components.split(",") if c]
    unknown = sorted(set(components) - set(COMPONENTS))
    if unknown:
        parser.error(f"unknown component(s) {', '.join(unknown)}")

    init_rclpy(["prog", *argv])
    node = BringupCheck(args.timeout, args.startup_timeout)
    logs = forward_logging_to_rosout(node)
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=_spin, args=(executor,), daemon=True)
    spinner.start()
    started = time.monotonic()
    print(f"bring-up check of {', '.join(components)}", flush=True)
    try:
        for component in components:
            if component in ("ee_x", "ee_y"):
                node.check_ee(component)
            elif component in ("ur_x", "ur_y"):
                node.check_ur(component)
            else:
                getattr(node, f"check_{component}")()
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    finally:
        # Shutting the context down wakes the executor; the node goes once nothing spins it.
        logs.remove()
        rclpy.try_shutdown()
        spinner.join(timeout=5.0)
        node.destroy_node()
    failed = [r for r in node.results if not r.ok]
    print(
        f"bring-up check: {len(node.results) - len(failed)} of {len(node.results)} checks passed "
        f"in {time.monotonic() - started:.1f} s",
        flush=True,
    )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
