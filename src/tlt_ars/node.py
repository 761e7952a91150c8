"""The ARS process (paper §IV.C, §V.C.1, §V.C.3): one per arm, ``--ars ars_x|ars_y``.

Serves, for the CRS:

* one action server per request on ``ros_names.ars_action(ars, request)``: ``AddCrossFrame``,
  ``AddMember``, ``AffixMember``, ``FoundationRivet``. A goal is **accepted** (the
  acknowledgement of Fig. 21) and then checked: when the ARS is idle, started, not paused, and
  the request makes sense against the mission (:meth:`ArsContext.check_request`), its branch is
  installed in the tree and run. Otherwise the goal is **aborted at once with the reason in
  ``result.reason``**: rclpy's goal callback can only accept or reject, and a rejection cannot
  carry a reason, so "rejected with a reason" is an accepted goal aborted before any motion
  (``result.success`` false, reason e.g. ``busy: running add_member bay1/vertical/x0_y1``).
  The one exception to "busy": a goal for the very request running now (same request, member and
  parameters, not being canceled) takes the running job over, and the older goal ends aborted as
  superseded. That is what a restarted CRS sends (its persisted model does not know the goal its
  predecessor had in flight), and what a CRS sends after it lost sight of the ARS on a broken
  link: either way the member is placed once and the result reaches the CRS that asks now.
  Feedback is the running leaf's path in the tree (``Add Member/Load Rivet/Approach Rivet
  Dispenser/Execute Approach Rivet Dispenser``) and the fraction of the branch's leaves done.
  The result is success, or failure with the failing step and its reason. A request that set its
  member (riveted, or a cross frame released) and then failed, or whose ARS was killed before it
  ended (the request is kept in ``--state-file``), or whose success the CRS never heard, is
  finished by the same request sent again: the ARS lets go, retreats from where the arm stands
  and reports success, instead of refusing the member as already placed. A part that a failed
  request left in the jaws (kept in the state file too) is discarded first by the next request.
  Cancel pre-empts the branch (the arm's trajectory goal is canceled, the driver holds the arm),
  waits until the JointState shows the arm stopped (≤ ``timeouts.stop_s``) and ends the goal
  CANCELED.
* ``SetBlackboardValue`` on ``ros_names.set_blackboard_service(ars)``: the ground's writes to this
  ARS's keys, forwarded by the CRS (:mod:`tlt_ars.ground_writes`): refused with the reason, or
  applied to the running configuration.
* ``GroundCommand`` on ``ros_names.ground_command_service(ars)``: Start (lets requests run; the
  ARS starts started when ``started_on_launch``), Pause (stops ticking and holds the arm: the
  running motion is canceled, Resume plans it again from where the arm stands), Resume, Stop
  (pre-empts everything, fails a running request with "stopped by ground command", waits for
  the arm to stand still and shuts the process down).

Subscribes to the CRS's ``MissionProgress`` to know what stands and which bay is current;
publishes the tree's status on ``ros_names.tree_status_topic(ars)`` and each shape's definition on
``ros_names.tree_definition_topic(ars)``.

Threads: a DirectMultiThreadedExecutor; the tick timer owns the tree; action callbacks hand jobs over
under a lock and wait for their result; planning runs in the context's planning thread.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np
import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions
from tlt_interfaces.msg import MissionProgress
from tlt_interfaces.srv import GroundCommand, SetBlackboardValue

from tlt_ars.behaviours.joint_check import joint_checks
from tlt_ars.command_line import build_parser, config_from_args
from tlt_ars.config import ArsConfig
from tlt_ars.context import ArsContext
from tlt_ars.goals import ACTION_TYPES, ActiveGoal, request_of
from tlt_ars.ground_writes import load_ground_writes
from tlt_ars.mission_checks import check_reach as check_reach_of_mission
from tlt_ars.mission_checks import prepare_for_mission
from tlt_ars.mission_state import Request
from tlt_ars.motion_planner import MotionPlanner
from tlt_ars.planning.reachability import UnreachableMember
from tlt_ars.request_data import RequestFile, RequestFileError
from tlt_ars.tree import ArsTree, Job
from tlt_common import ros_names
from tlt_common.bt.ros import TreeStatusPublisher
from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import load_mission
from tlt_common.ros.direct_executor import DirectMultiThreadedExecutor
from tlt_common.ros.executor_stop import stop_executor
from tlt_common.ros.interpreter_lock import share_the_interpreter_quickly
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.node_teardown import destroy_node
from tlt_common.ros.periodic_timer import create_periodic_timer
from tlt_common.ros.rosout_logging import forward_logging_to_rosout, init_rclpy
from tlt_common.ros.sim_clock_watch import watch_sim_clock
from tlt_common.ros.stop_signals import stop_on_signals
from tlt_common.ros.topic_silence_watch import TopicSilenceWatch

# How long a goal the mission check refuses waits for a fresher MissionProgress (the CRS sends one
# on every model change and at progress_rate_hz), wall seconds.
FRESH_PROGRESS_WAIT_S = 2.0


class ArsNode(LeanNode):
    """One ARS; see the module docstring."""

    def __init__(self, config: ArsConfig, *, context: Any = None, check_reach: bool | None = None) -> None:
        super().__init__(config.ars, context=context)
        try:
            self._start(config, check_reach)
        except BaseException:
            # A node that failed to start would keep its DDS participant in the graph until the
            # garbage collector found it: a process that goes on (a launcher, a test) would see it.
            destroy_node(self)
            raise

    def _start(self, config: ArsConfig, check_reach: bool | None) -> None:
        self.config = config
        self.ars = config.ars
        mission = load_mission(config.mission_path)
        from tlt_ars.planning.world import load_scene_config

        scene = load_scene_config(config.scene_path)
        config = self.config = prepare_for_mission(config, mission, scene)
        if config.raw["check_reach"] if check_reach is None else check_reach:
            # A member out of this arm's reach is found now, not mid-build (§V.D).
            report = check_reach_of_mission(config, mission, scene)
            if not report.ok:
                raise UnreachableMember(mission.name, report.issues)
        state = config.state_path
        self.ctx = ArsContext(
            self,
            config,
            mission,
            scene,
            request_file=RequestFile(state, mission, self.ars) if state is not None else None,
        )
        if self.ctx.unfinished is not None:
            left = self.ctx.unfinished
            how = (
                f"set its member ({left.recorded})"
                if left.recorded
                else f"began the step that sets its member ({left.setting}) and never saw it end"
            )
            self.get_logger().warning(
                f"{state}: {left.request.request} of '{left.member.id}' {how} before this ARS went"
                " down; the same request sent again finishes it"
            )
        self.planner = MotionPlanner(
            scene,
            self.ars,
            mission,
            config.arm["joint_names"],
            velocity_scale=config.arm["velocity_scale"],
            sample_period=config.arm["sample_period_s"],
            time_limit=config.arm["planning_time_s"],
        )
        self._lock = threading.RLock()
        self.started = bool(config.raw["started_on_launch"])
        self.paused = False
        self._held = False
        self._paused_since: float | None = None  # mission time of the Pause not yet resumed
        self.stop_requested = False
        self.finished = threading.Event()
        self._stop_since: float | None = None
        self.active: ActiveGoal | None = None
        self._goals: dict[bytes, ActiveGoal] = {}
        self.tree = ArsTree(self.ctx, self.planner, lambda: self.started)
        self.status = TreeStatusPublisher(
            self,
            self.ars,
            topic=ros_names.tree_status_topic(self.ars),
            definition_topic=ros_names.tree_definition_topic(self.ars),
            period_s=1.0 / config.raw["status_rate_hz"],
        )
        # The request's feedback goes out before the tree's status: the CRS waits on the first one.
        self.tree.tree.add_post_tick_handler(lambda _tree: self._send_feedback(self.active))
        self.status.attach(self.tree.tree)
        self.tree.on_change.append(self.status.refresh)

        goals = ReentrantCallbackGroup()
        self._servers = [
            ActionServer(
                self,
                action_type,
                ros_names.ars_action(self.ars, kind),
                execute_callback=lambda handle, kind=kind: self._execute(kind, handle),
                goal_callback=lambda _goal: GoalResponse.ACCEPT,
                handle_accepted_callback=lambda handle, kind=kind: self._accepted(kind, handle),
                cancel_callback=self._cancel,
                callback_group=goals,
            )
            for kind, action_type in ACTION_TYPES.items()
        ]
        self.create_service(
            GroundCommand, ros_names.ground_command_service(self.ars), self._on_ground, callback_group=goals
        )
        self.ground_writes = load_ground_writes(config.raw, config.writable_blackboard_path)
        self.create_service(
            SetBlackboardValue,
            ros_names.set_blackboard_service(self.ars),
            self._on_set_blackboard,
            callback_group=goals,
        )
        self._progress_changed = threading.Condition()
        self._progress_count = 0
        self.create_subscription(
            MissionProgress,
            ros_names.CRS_MISSION_PROGRESS,
            self._on_progress,
            10,
            callback_group=MutuallyExclusiveCallbackGroup(),
        )
        ticks = MutuallyExclusiveCallbackGroup()
        # A request's first tick runs when its goal is accepted (_accepted), not at the next period.
        self._timer = create_periodic_timer(
            self, 1.0 / config.raw["tick_rate_hz"], self._tick, callback_group=ticks
        )

    # ----- goals -----
    def _refusal(self, request: Request) -> str | None:
        if self.stop_requested:
            return "stopped by ground command"
        if not self.started:
            return f"{self.ars} is not started (waiting for the ground's Start)"
        if self.paused:
            return f"{self.ars} is paused"
        if self.active is not None:
            a = self.active.request
            return f"busy: {self.ars} is running {a.request} for '{a.member_id}'"
        return self.ctx.check_request(request)

    def _accepted(self, kind: str, handle: Any) -> None:
        request = request_of(kind, handle.request)
        if self.ctx.check_request(request) is not None and self.ctx.state.mission_refusal(request) is None:
            # The CRS sends a request right after the model change that allows it (an affix after
            # the placement), and the MissionProgress carrying that change travels on its own
            # topic: the mission check is made on a progress message newer than the goal. What the
            # mission alone refuses no progress changes, and is refused at once.
            self._await_progress(FRESH_PROGRESS_WAIT_S)
        started = False
        with self._lock:
            goal = ActiveGoal(kind, handle, request, threading.Event())
            running = self.active
            if (
                running is not None
                and running.request == request
                and not running.cancel_requested
                and not self.stop_requested
            ):
                self._take_over(running, goal)
            elif (reason := self._refusal(request)) is not None:
                goal.outcome = ("aborted", f"rejected: {reason}")
                goal.done.set()
            else:
                self.active = goal
                self.tree.submit(Job(request, lambda ok, why, g=goal: self._finish(g, ok, why)))
                started = True
            self._goals[bytes(handle.goal_id.uuid)] = goal
        handle.execute()
        if started:
            # The request's first tick runs here, on the thread that accepted it, rather than on
            # the tick group's thread after a guard condition wakes the executor: the CRS waits on
            # that tick's feedback. Ticks are serialised by the lock, whichever thread runs them.
            self._tick()

    def _take_over(self, running: ActiveGoal, goal: ActiveGoal) -> None:
        """``goal`` follows the job of ``running`` (the same request) from here; ``running`` ends."""
        running.successor = goal
        running.outcome = ("aborted", "superseded: a newer goal for the same request follows the job")
        running.done.set()
        self.active = goal
        self.get_logger().warning(
            f"a new goal for the running {goal.kind} of '{goal.request.member_id}' takes it over"
            " (the CRS restarted, or lost sight of this ARS)"
        )

    def _execute(self, kind: str, handle: Any) -> Any:
        with self._lock:
            goal = self._goals.pop(bytes(handle.goal_id.uuid))
        result_type = ACTION_TYPES[kind].Result
        # The tick sends the feedback; the tree's own timeouts bound the request.
        while not goal.done.wait(0.1):
            if self.finished.is_set() or not rclpy.ok(context=self.context):
                goal.outcome = ("aborted", "the ARS shut down")
                break
        state, reason = goal.outcome or ("aborted", "no outcome")
        result = result_type()
        result.success = state == "succeeded"
        result.reason = reason
        if hasattr(result, "discarded_from"):
            result.parts_discarded = len(goal.discarded_from)
            result.discarded_from = list(goal.discarded_from)
        if hasattr(result, "joints"):
            result.joints = list(goal.joints)
        if state == "succeeded":
            handle.succeed()
        elif state == "canceled" and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        return result

    def _finish(self, goal: ActiveGoal, ok: bool, reason: str) -> None:
        """Called from the tick (Report Result, or a build failure)."""
        while goal.successor is not None:  # the job was taken over by a newer goal
            goal = goal.successor
        goal.discarded_from = list(self.ctx.data.discarded_from)
        goal.joints = joint_checks(self.ctx.data)
        self.ctx.end(goal.request)
        goal.outcome = ("succeeded", "") if ok else ("aborted", reason)
        with self._lock:
            if self.active is goal:
                self.active = None
        goal.done.set()

    def _cancel(self, handle: Any) -> CancelResponse:
        with self._lock:
            goal = self.active
            if goal is None or goal.handle is not handle:
                return CancelResponse.REJECT
            goal.cancel_requested = True
        return CancelResponse.ACCEPT

    # ----- ground commands -----
    def _on_set_blackboard(self, request: Any, response: Any) -> Any:
        with self._lock:
            self.ground_writes.on_request(request, response)
        if response.accepted:
            self.get_logger().info(f"{request.key} set by the ground")
        else:
            self.get_logger().warning(f"ground write of {request.key} refused: {response.reason}")
        return response

    def _on_ground(self, request: Any, response: Any) -> Any:
        cmd = request.command
        with self._lock:
            response.accepted, response.reason = True, ""
            if self.stop_requested:
                response.accepted, response.reason = False, "stopping"
            elif cmd == GroundCommand.Request.START:
                if self.paused:
                    response.accepted, response.reason = False, "paused: Resume continues"
                elif self.started:
                    response.reason = "already started"
                self.started = self.started or not self.paused
            elif cmd == GroundCommand.Request.PAUSE:
                if self.paused:
                    response.accepted, response.reason = False, "already paused"
                else:
                    self.paused, self._held = True, False
            elif cmd == GroundCommand.Request.RESUME:
                if not self.paused:
                    response.accepted, response.reason = False, "not paused"
                self.paused = False
            elif cmd == GroundCommand.Request.STOP:
                self.stop_requested = True
            else:
                response.accepted, response.reason = False, f"unknown command {cmd}"
        return response

    def _on_progress(self, msg: Any) -> None:
        self.ctx.state.apply_progress(msg)
        with self._progress_changed:
            self._progress_count += 1
            self._progress_changed.notify_all()

    def _await_progress(self, timeout_s: float) -> bool:
        """Wait (at most ``timeout_s``) for a MissionProgress received after this call."""
        with self._progress_changed:
            seen = self._progress_count
            return self._progress_changed.wait_for(lambda: self._progress_count > seen, timeout_s)

    # ----- the tick -----
    def _arm_stopped(self) -> bool:
        v = self.ctx.arm_velocity()
        return v is not None and float(np.max(np.abs(v))) <= self.config.arm["stopped_velocity"]

    def _tick(self) -> None:
        with self._lock:
            if self.finished.is_set():
                return
            now = self.ctx.clock()
            goal = self.active
            if self.stop_requested:
                if self._stop_since is None:
                    self._stop_since = now
                    self.tree.interrupt()
                    self._end(goal, "aborted", "stopped by ground command")
                if self._arm_stopped() or now - self._stop_since > self.config.timeouts["stop_s"]:
                    self.finished.set()
                return
            if goal is not None and goal.cancel_requested:
                if goal.stopping_since is None:
                    goal.stopping_since = now
                    self.tree.interrupt()
                if self._arm_stopped():
                    self._end(goal, "canceled", "canceled by the CRS; the arm is stopped")
                elif now - goal.stopping_since > self.config.timeouts["stop_s"]:
                    self._end(
                        goal,
                        "canceled",
                        "canceled; the arm did not report standing still within"
                        f" {self.config.timeouts['stop_s']:g} s",
                    )
                return
            if self.paused:
                if not self._held:
                    self.tree.hold()
                    self._held = True
                    if self._paused_since is None:
                        self._paused_since = now
                return
            if self._paused_since is not None:
                self.tree.resume(now - self._paused_since)
                self._paused_since = None
            try:
                self.tree.tick()
            except Exception as exc:  # a behaviour bug fails the request; the ARS keeps serving
                self.get_logger().error(f"tick failed: {exc!r}")
                self.tree.interrupt()
                self._end(goal, "aborted", f"internal error in the behaviour tree: {exc!r}")

    def _send_feedback(self, goal: ActiveGoal | None) -> None:
        """The running step to the CRS, at the end of the tick that changed it (the first one
        tells the CRS that the tree runs its request)."""
        step, progress = self.tree.step(), float(self.tree.progress())
        if goal is None or not step or goal.outcome is not None or goal.feedback == (step, progress):
            return
        goal.feedback = (step, progress)
        goal.handle.publish_feedback(ACTION_TYPES[goal.kind].Feedback(step=step, progress=progress))

    def _end(self, goal: ActiveGoal | None, state: str, reason: str) -> None:
        if goal is None:
            return
        goal.discarded_from = list(self.ctx.data.discarded_from)
        goal.joints = joint_checks(self.ctx.data)
        self.ctx.end(goal.request)
        goal.outcome = (state, reason)
        if self.active is goal:
            self.active = None
        goal.done.set()

    def close(self) -> None:
        self.finished.set()
        self.ctx.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ARS; ``--ros-args ...`` (e.g. ``-p use_sim_time:=true``) go to rclpy."""
    from rclpy.utilities import remove_ros_args

    full = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(remove_ros_args(["ars", *full])[1:])
    try:
        config = config_from_args(args)
    except (ConfigError, OSError) as exc:
        print(f"ars: {exc}", file=sys.stderr)
        return 2
    share_the_interpreter_quickly()  # the planner works beside the tick and the executor's threads
    stop = stop_on_signals()
    init_rclpy(["ars", *full], signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = ArsNode(config, check_reach=False if args.no_reach_check else None)
    except (ConfigError, RequestFileError, ValueError, OSError) as exc:
        print(f"ars: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    logs = forward_logging_to_rosout(node)
    executor = DirectMultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    clock_watch = watch_sim_clock(node)
    ctx = node.ctx
    silence_watch = TopicSilenceWatch(ctx.cache, [ctx.joint_topic, ctx.arm_status_topic, ctx.ee_topic],
                                      node.get_name()).start()  # fmt: skip
    try:
        while not stop and rclpy.ok() and not node.finished.is_set():
            executor.spin_once(timeout_sec=0.1)
        # After a ground Stop, let the last goal results go out before the process ends.
        for _ in range(10):
            if stop or not rclpy.ok():
                break
            executor.spin_once(timeout_sec=0.05)
    except ExternalShutdownException:  # the context shut down by someone else
        pass
    finally:
        if clock_watch is not None:
            clock_watch.stop()
        silence_watch.stop()
        node.close()
        for exc in stop_executor(executor, 2.0):  # before the node's handles go
            node.get_logger().warning(f"a callback ended with {exc!r} at shutdown")
        logs.remove()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
