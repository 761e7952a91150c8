"""Thin rclpy adapters exposing the controllers as ROS interfaces, the way ros2_control's controllers do.

* :class:`TrajectoryActionServer`: a ``tlt_interfaces/action/FollowJointTrajectory`` server over a
  :class:`~tlt_drivers.controllers.trajectory.JointTrajectoryController`. Every goal is accepted and
  handed to the controller; one that fails validation (or the motion gate) ends at once as ABORTED
  with the controller's error code and reason in the result; every goal, once ended, is recorded on
  ``/<component>/executed_trajectories`` (:mod:`.executed_trajectories`). The execute coroutine never blocks:
  it awaits a future that :meth:`TrajectoryActionServer.tick`, called by the node's control loop
  after the controller's update, resolves when the goal ends. A new goal replaces the running one
  (the old ends ABORTED with "replaced by a new goal"); a cancel request stops where the joints are.
* :class:`GroupPositionCommandSubscriber`: a ``std_msgs/Float64MultiArray`` command topic over a
  :class:`~tlt_drivers.controllers.group_position.JointGroupPositionController`. A rejected command
  is logged and its reason published on ``<topic>/rejected`` (``std_msgs/String``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray, String
from tlt_interfaces.action import FollowJointTrajectory
from trajectory_msgs.msg import JointTrajectoryPoint

from tlt_common import ros_names
from tlt_drivers.controllers import executed_trajectories
from tlt_drivers.controllers.group_position import CommandRejected, JointGroupPositionController
from tlt_drivers.controllers.trajectory import (
    ExecutingGoal,
    GoalStatus,
    JointTrajectoryController,
    TrajectoryGoal,
    TrajectoryPoint,
)


def _duration_s(duration) -> float:
    return duration.sec + duration.nanosec * 1e-9


def goal_from_msg(goal_msg) -> TrajectoryGoal:
    """Convert a FollowJointTrajectory goal message to the controller's plain goal."""
    traj = goal_msg.trajectory
    points = tuple(
        TrajectoryPoint(_duration_s(p.time_from_start), tuple(p.positions), tuple(p.velocities))
        for p in traj.points
    )
    return TrajectoryGoal(
        joint_names=tuple(traj.joint_names),
        points=points,
        path_tolerance={t.name: t.position for t in goal_msg.path_tolerance},
        goal_tolerance={t.name: t.position for t in goal_msg.goal_tolerance},
        goal_time_tolerance=_duration_s(goal_msg.goal_time_tolerance),
        goal_velocity_tolerance={t.name: t.velocity for t in goal_msg.goal_tolerance},
    )


class TrajectoryActionServer:
    """``component``'s FollowJointTrajectory action on ``node``, driving ``controller``."""

    def __init__(
        self,
        node: Node,
        component: str,
        controller: JointTrajectoryController,
        actual: Callable[[], Mapping[str, float]],
        now: Callable[[], float],
        *,
        feedback_every: int = 5,
    ) -> None:
        self._node = node
        self._controller = controller
        self._actual = actual
        self._now = now
        self._feedback_every = max(1, feedback_every)
        self._ticks = 0
        self._pending: list[tuple[ExecutingGoal, ServerGoalHandle, Future]] = []
        self.executed = executed_trajectories.ExecutedTrajectoryPublisher(node, component)
        self.server = ActionServer(
            node,
            FollowJointTrajectory,
            ros_names.trajectory_action(component),
            execute_callback=self._execute,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=lambda _handle: CancelResponse.ACCEPT,
        )

    async def _execute(self, goal_handle) -> FollowJointTrajectory.Result:
        started = self.executed.now()
        executing = self._controller.start(goal_from_msg(goal_handle.request), self._now(), self._actual())
        if not executing.done:
            done = Future()
            self._pending.append((executing, goal_handle, done))
            await done
        result = FollowJointTrajectory.Result()
        result.error_code = executing.error_code
        result.error_string = executing.error_string
        if executing.status == GoalStatus.SUCCEEDED:
            goal_handle.succeed()
            outcome = executed_trajectories.SUCCEEDED
        elif executing.status == GoalStatus.CANCELED and goal_handle.is_cancel_requested:
            goal_handle.canceled()
            outcome = executed_trajectories.CANCELED
        else:
            goal_handle.abort()
            outcome = executed_trajectories.ABORTED
        trajectory = goal_handle.request.trajectory
        self.executed.publish(
            started, trajectory.joint_names, executed_trajectories.planned_seconds(trajectory), outcome,
            result.error_code, result.error_string,
        )  # fmt: skip
        return result

    def tick(self) -> None:
        """Resolve ended goals, act on cancel requests, publish feedback; call after each update."""
        self._ticks += 1
        still = []
        for executing, goal_handle, done in self._pending:
            if not executing.done and goal_handle.is_cancel_requested:
                self._controller.cancel(self._actual())
            if executing.done or not goal_handle.is_active:
                done.set_result(True)
                continue
            if self._ticks % self._feedback_every == 0 and executing.desired:
                goal_handle.publish_feedback(self._feedback(executing))
            still.append((executing, goal_handle, done))
        self._pending = still

    def _feedback(self, executing: ExecutingGoal) -> FollowJointTrajectory.Feedback:
        fb = FollowJointTrajectory.Feedback()
        fb.header.stamp = self._node.get_clock().now().to_msg()
        names = list(executing.goal.joint_names)
        fb.joint_names = names
        fb.desired = JointTrajectoryPoint(
            positions=[executing.desired[n] for n in names],
            velocities=[executing.desired_velocity.get(n, 0.0) for n in names],
        )
        fb.actual = JointTrajectoryPoint(positions=[executing.actual[n] for n in names])
        fb.error = JointTrajectoryPoint(positions=[executing.desired[n] - executing.actual[n] for n in names])
        return fb

    def destroy(self) -> None:
        for _, _, done in self._pending:
            if not done.done():
                done.set_result(False)
        self._pending = []
        self.server.destroy()


class GroupPositionCommandSubscriber:
    """``Float64MultiArray`` on ``topic`` -> ``controller.set_command``; rejections on ``topic/rejected``."""

    def __init__(self, node: Node, topic: str, controller: JointGroupPositionController) -> None:
        self._node = node
        self._controller = controller
        self.rejected_pub = node.create_publisher(String, f"{topic}/rejected", 10)
        self.subscription = node.create_subscription(Float64MultiArray, topic, self._on_command, 10)

    def _on_command(self, msg: Float64MultiArray) -> None:
        try:
            self._controller.set_command(list(msg.data))
        except CommandRejected as exc:
            self._node.get_logger().warning(f"position command rejected: {exc}")
            self.rejected_pub.publish(String(data=str(exc)))


__all__ = ["GroupPositionCommandSubscriber", "TrajectoryActionServer", "goal_from_msg"]
