"""End-effector behaviours (paper §V.B.4): grasp and release, the width joint, the rivet guns, and
their verification from the EE's own sensors.

Interfaces of the EE driver (``ee_x`` / ``ee_y``): the grasp joints through FollowJointTrajectory
(``ros_names.trajectory_action(ee(ars))``), the width joint through a group position command
(``ros_names.position_command_topic(ee(ars))``, ``std_msgs/Float64MultiArray``), the rivet guns
through ``/<ee>/set_rivet_gun`` (``SetActuatorState``), and ``EndEffectorState`` on
``ros_names.state_topic(ee(ars))``, whose ``part_grasped`` comes from the grasp servos' position and
load. Every verification waits for a state message that arrived after the action it checks.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import py_trees
from py_trees.common import Status
from std_msgs.msg import Float64MultiArray
from tlt_interfaces.action import FollowJointTrajectory
from tlt_interfaces.msg import JointTolerance
from tlt_interfaces.srv import SetActuatorState
from trajectory_msgs.msg import JointTrajectoryPoint

from tlt_ars.context import ArsContext
from tlt_ars.motion_planner import duration_msg
from tlt_ars.request_data import RequestData
from tlt_common import ros_names
from tlt_common.bt.nodes import Action
from tlt_common.bt.ros import ActionGoal, shared_service_client


def rivet_gun_service(ars: str) -> str:
    """The EE driver's rivet-gun service (``/<ee>/set_rivet_gun``)."""
    return f"/{ros_names.ee(ars)}/set_rivet_gun"


def _trajectory_ok(result: Any) -> tuple[bool, str]:
    code = getattr(result, "error_code", 0)
    return code == 0, f"error {code}: {getattr(result, 'error_string', '')}"


class MoveGrasp(ActionGoal):
    """Open or close the grasp joints through the EE's trajectory controller.

    Reads EndEffectorState (``calibrated``); writes nothing on the blackboard. RUNNING while the
    EE is not calibrated yet (its driver refuses every motion until the width joint is zeroed on
    its limit switch: after power-up, or after it rebooted a servo), at most ``timeouts.width_s``
    (the calibration moves the width joint), then while the jaws move; SUCCESS when the driver
    reports the trajectory done; FAILURE when the EE stays uncalibrated, on rejection, abort or
    timeout. No path tolerance, and no goal tolerance when closing: jaws closing on a part stop
    short of their goal by design, and grasp and release are judged from the servo load instead.
    """

    def __init__(self, name: str, ctx: ArsContext, *, close: bool) -> None:
        self.ctx = ctx
        self.close = close
        ee = ctx.config.ee
        super().__init__(
            name,
            ctx.node,
            FollowJointTrajectory,
            ros_names.trajectory_action(ros_names.ee(ctx.ars)),
            self._make_goal,
            server_timeout=ctx.config.timeouts["server_s"],
            result_timeout=ee["grasp_time_s"] + ctx.config.timeouts["trajectory_margin_s"],
            result_ok=_trajectory_ok,
            clock=ctx.clock,
        )

    def initialise(self) -> None:
        super().initialise()
        self._calibrated = False

    def update(self) -> Status:
        if not self._calibrated:
            entry = self.ctx.cache.latest(self.ctx.ee_topic)
            # a faulted EE is left to refuse the goal, with its driver's reason
            if entry is None or entry[0].calibrated or entry[0].fault:
                self._calibrated = True
                self._started = self.clock()  # the server's wait starts now
            elif self.clock() - self._started > self.ctx.config.timeouts["width_s"]:
                return self.fail(
                    f"end effector not calibrated within {self.ctx.config.timeouts['width_s']:g} s"
                    " (its width joint is zeroed on the limit switch before any motion)"
                )
            else:
                self.feedback_message = "waiting for the end effector to calibrate"
                return Status.RUNNING
        return super().update()

    def _make_goal(self) -> Any:
        ee = self.ctx.config.ee
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = list(ee["grasp_joints"])
        t = ee["grasp_time_s"]
        point = JointTrajectoryPoint(
            positions=[float(v) for v in ee["grasp_closed" if self.close else "grasp_open"]]
        )
        point.time_from_start = duration_msg(t)
        goal.trajectory.points = [point]
        # The jaws are judged by the servos' load (Verify Grasp / Verify Released), not by how
        # closely they track: no path limit either way, and no goal limit when closing on a part.
        goal.path_tolerance = [JointTolerance(name=n, position=-1.0) for n in ee["grasp_joints"]]
        if self.close:
            goal.goal_tolerance = [JointTolerance(name=n, position=-1.0) for n in ee["grasp_joints"]]
        return goal


class AwaitEeState(Action):
    """Wait for an EndEffectorState that arrived after this behaviour started and satisfies
    ``predicate``.

    Reads: ``/<ee>/state``. RUNNING until such a message arrives (≤ ``timeout``). SUCCESS when it
    does. FAILURE on timeout, with ``describe(latest state)`` saying what the sensor showed, or when
    the EE reports a fault.
    """

    def __init__(self, name: str, ctx: ArsContext, predicate: Callable[[Any], bool],
                 describe: Callable[[Any], str], timeout: float) -> None:  # fmt: skip
        super().__init__(name)
        self.ctx, self.predicate, self.describe, self.timeout = ctx, predicate, describe, timeout
        self._started = 0.0

    def initialise(self) -> None:
        self._started = self.ctx.clock()

    def update(self) -> Status:
        entry = self.ctx.cache.latest(self.ctx.ee_topic)
        now = self.ctx.clock()
        fresh = entry is not None and entry[1] >= self._started
        if fresh and entry[0].fault:
            return self.fail(f"end effector fault: {entry[0].fault_reason}")
        if fresh and self.predicate(entry[0]):
            self.feedback_message = "confirmed by the end effector"
            return Status.SUCCESS
        if now - self._started > self.timeout:
            seen = self.describe(entry[0]) if entry is not None else f"no state on '{self.ctx.ee_topic}'"
            return self.fail(f"{self.name}: not confirmed within {self.timeout:g} s ({seen})")
        return Status.RUNNING


def _grasp_text(state: Any) -> str:
    efforts = ", ".join(f"{n}={e:+.2f}" for n, e in zip(state.joint_names, state.effort, strict=False))
    return f"part_grasped={state.part_grasped}; loads {efforts}"


def verify_grasp(ctx: ArsContext, name: str = "Verify Grasp") -> AwaitEeState:
    """Grasp verified from the EE servos' feedback (``part_grasped``)."""
    return AwaitEeState(
        name, ctx, lambda s: bool(s.part_grasped), _grasp_text, ctx.config.timeouts["sensor_s"]
    )


def verify_released(ctx: ArsContext, name: str = "Verify Released") -> AwaitEeState:
    """The servos no longer hold a part."""
    return AwaitEeState(name, ctx, lambda s: not s.part_grasped, _grasp_text, ctx.config.timeouts["sensor_s"])


def grasp(ctx: ArsContext) -> py_trees.composites.Sequence:
    """``Sequence[Close Grasp, Verify Grasp]``."""
    seq = py_trees.composites.Sequence("Grasp", memory=True)
    seq.add_children([MoveGrasp("Close Grasp", ctx, close=True), verify_grasp(ctx)])
    return seq


def release(ctx: ArsContext) -> py_trees.composites.Sequence:
    """``Sequence[Open Grasp, Verify Released]``; the held part is forgotten once released."""
    seq = py_trees.composites.Sequence("Release", memory=True)
    seq.add_children(
        [
            MoveGrasp("Open Grasp", ctx, close=False),
            verify_released(ctx),
            KeepData("Part Released", ctx, holding=None),
        ]
    )
    return seq


class KeepData(Action):
    """Write ``fields`` into ``RequestData`` and keep them in the state file, so that a restarted
    ARS knows them: Rivet In Gun notes the rivet Verify Rivet Loaded saw in the gun (a request
    after a failed one loads no other), Part Released forgets the held part after a verified
    release. SUCCESS at once; FAILURE when the state file cannot be written."""

    def __init__(self, name: str, ctx: ArsContext, **fields: object) -> None:
        super().__init__(name)
        unknown = sorted(set(fields) - set(RequestData.__dataclass_fields__))
        if unknown:
            raise ValueError(f"{name}: RequestData has no field {', '.join(unknown)}")
        self.ctx, self.fields = ctx, fields

    def update(self) -> Status:
        for key, value in self.fields.items():
            setattr(self.ctx.data, key, value)
        if (why := self.ctx.keep()) is not None:
            return self.fail(why)
        return Status.SUCCESS


class SetWidth(Action):
    """Drive the EE width joint to the width for ``part_kind`` and wait until the servo is there.

    Reads: EndEffectorState (the width joint's position). Writes: a position command, and the
    target as ``ArsContext.width_target`` (motions planned meanwhile are checked over the move).
    RUNNING until a state newer than the command shows the width within ``width_tolerance`` (the
    command is repeated each second, since a command topic may not be matched yet). SUCCESS
    then. FAILURE after ``timeouts.width_s``, or on an EE fault, naming where the joint stood.
    """

    def __init__(self, name: str, ctx: ArsContext, part_kind: str | Callable[[], str]) -> None:
        super().__init__(name)
        self.ctx = ctx
        self.part_kind = part_kind
        self.publisher = ctx.width_publisher
        self._started = 0.0
        self._sent = -1e9
        self._target = 0.0

    def initialise(self) -> None:
        kind = self.part_kind() if callable(self.part_kind) else self.part_kind
        self._target = float(self.ctx.config.ee["width"][kind])
        self._started = self.ctx.clock()
        self._sent = -1e9
        self.ctx.width_target = self._target

    def update(self) -> Status:
        now = self.ctx.clock()
        if now - self._sent >= 1.0:
            self.publisher.publish(Float64MultiArray(data=[self._target]))
            self._sent = now
        ee = self.ctx.config.ee
        entry = self.ctx.cache.latest(self.ctx.ee_topic)
        width = None
        if entry is not None and ee["width_joint"] in entry[0].joint_names:
            width = entry[0].position[list(entry[0].joint_names).index(ee["width_joint"])]
            if entry[0].fault and entry[1] >= self._started:
                return self.fail(f"end effector fault: {entry[0].fault_reason}")
            if entry[1] >= self._started and abs(width - self._target) <= ee["width_tolerance"]:
                self.feedback_message = f"width {width:.4f} m"
                return Status.SUCCESS
        if now - self._started > self.ctx.config.timeouts["width_s"]:
            where = "unknown" if width is None else f"{width:.4f} m"
            return self.fail(
                f"width joint did not reach {self._target:.4f} m within"
                f" {self.ctx.config.timeouts['width_s']:g} s (at {where})"
            )
        self.feedback_message = f"width to {self._target:.4f} m"
        return Status.RUNNING


class CommandWidth(Action):
    """Command the EE width joint to the width for ``part_kind`` and go on without waiting.

    Reads: nothing. Writes: a position command, and the target as ``ArsContext.width_target``.
    SUCCESS on the tick it is sent. For a width nothing after it in the request needs (Retract
    Width, the last step of a diagonal's request): the slide moves while the CRS goes on, every
    motion planned meanwhile is checked over the rest of its move (PlanMotion), and the next Set
    Width waits for it and judges where it stands.
    """

    def __init__(self, name: str, ctx: ArsContext, part_kind: str) -> None:
        super().__init__(name)
        self.ctx = ctx
        self.part_kind = part_kind

    def update(self) -> Status:
        target = float(self.ctx.config.ee["width"][self.part_kind])
        self.ctx.width_publisher.publish(Float64MultiArray(data=[target]))
        self.ctx.width_target = target
        self.feedback_message = f"width to {target:.4f} m"
        return Status.SUCCESS


class FireRivetGun(Action):
    """Fire the configured rivet gun: output on, hold ``fire_s``, output off (paper §V.B.4: GPIO).

    Reads: EndEffectorState.rivet_gun_output (the GPIO output read back). Writes:
    ``RequestData.rivet_in_gun`` (false once the output was on for ``fire_s``). RUNNING while the
    service calls go out and the gun fires. SUCCESS once the output was seen on and then off.
    FAILURE when the service refuses or is missing, or the state never shows the output.
    Pre-empted while firing: the output is switched off.
    """

    def __init__(self, name: str, ctx: ArsContext) -> None:
        super().__init__(name)
        self.ctx = ctx
        self.gun = ctx.config.ee["rivet_gun"]
        self.index = int(self.gun.rsplit("_", 1)[-1]) if self.gun.rsplit("_", 1)[-1].isdigit() else 0
        self.client = shared_service_client(ctx.node, SetActuatorState, rivet_gun_service(ctx.ars))
        self._phase = "idle"
        self._future = None
        self._since = 0.0

    def initialise(self) -> None:
        self._phase = "call_on"
        self._future = None
        self._since = self.ctx.clock()

    def _call(self, state: str) -> Any:
        return self.client.call_async(SetActuatorState.Request(actuator=self.gun, state=state))

    def _output(self) -> bool | None:
        entry = self.ctx.cache.latest(self.ctx.ee_topic)
        if entry is None or entry[1] < self._since:
            return None
        outputs = list(entry[0].rivet_gun_output)
        return bool(outputs[self.index]) if self.index < len(outputs) else None

    def update(self) -> Status:
        now = self.ctx.clock()
        timeout = self.ctx.config.timeouts["service_s"]
        if self._phase in ("call_on", "call_off") and self._future is None:
            if not self.client.service_is_ready():
                if now - self._since > self.ctx.config.timeouts["server_s"]:
                    return self.fail(f"service '{rivet_gun_service(self.ctx.ars)}' not available")
                return Status.RUNNING
            self._future = self._call("on" if self._phase == "call_on" else "off")
            self._since = now
            return Status.RUNNING
        if self._future is not None:
            if not self._future.done():
                if now - self._since > timeout:
                    return self.fail(
                        f"no answer from '{rivet_gun_service(self.ctx.ars)}' within {timeout:g} s"
                    )
                return Status.RUNNING
            reply, self._future = self._future.result(), None
            if not reply.accepted:
                return self.fail(f"rivet gun refused: {reply.reason}")
            self._phase = "firing" if self._phase == "call_on" else "check_off"
            self._since = now
            return Status.RUNNING
        if self._phase == "firing":
            seen = self._output()
            if seen is True and now - self._since >= self.ctx.config.ee["fire_s"]:
                self._phase = "call_off"
                self._since = now
                self.ctx.data.rivet_in_gun = False  # the record right after writes the state file
            elif now - self._since > self.ctx.config.timeouts["sensor_s"] + self.ctx.config.ee["fire_s"]:
                self._phase = "call_off"  # switch it off before failing
                return self.fail(f"{self.gun} output never showed on in the end-effector state")
            self.feedback_message = f"{self.gun} firing"
            return Status.RUNNING
        if self._phase == "check_off":
            if self._output() is False:
                self._phase = "idle"
                self.feedback_message = f"{self.gun} fired"
                return Status.SUCCESS
            if now - self._since > self.ctx.config.timeouts["sensor_s"]:
                return self.fail(f"{self.gun} output still on in the end-effector state")
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        pending_on = self._phase == "call_on" and self._future is not None
        firing = self._phase in ("firing", "call_off") or pending_on
        if firing and self.client.service_is_ready():
            # Never leave a gun firing: switch it off whatever pre-empted or failed the firing.
            self._call("off")
        self._phase = "idle"
        self._future = None


__all__ = [
    "AwaitEeState",
    "CommandWidth",
    "FireRivetGun",
    "KeepData",
    "MoveGrasp",
    "SetWidth",
    "grasp",
    "release",
    "rivet_gun_service",
    "verify_grasp",
    "verify_released",
]
