"""The record of every trajectory goal a driver ran: ``tlt_interfaces/ExecutedTrajectory`` on
``/<component>/executed_trajectories``, published once per goal when it ends.

A goal's trajectory says how long its motion should take (its last point's ``time_from_start``);
the record puts that next to when the controller started it and when it ended, on the driver's
clock (sim time on the twin), with the outcome. The recorder keeps these with the rest of a run's
traffic, so where a build's time went can be read back afterwards: in motion or between motions
(``bench/build.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

from builtin_interfaces.msg import Time
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from tlt_interfaces.msg import ExecutedTrajectory

from tlt_common import ros_names
from tlt_common.ros.stamps import stamp_seconds

SUCCEEDED = ExecutedTrajectory.OUTCOME_SUCCEEDED
ABORTED = ExecutedTrajectory.OUTCOME_ABORTED
CANCELED = ExecutedTrajectory.OUTCOME_CANCELED


def planned_seconds(trajectory) -> float:
    """A ``trajectory_msgs/JointTrajectory``'s own duration (0 for one without points)."""
    return stamp_seconds(trajectory.points[-1].time_from_start) if trajectory.points else 0.0


class ExecutedTrajectoryPublisher:
    """Publishes the record of each ended goal of ``component``'s trajectory controller."""

    def __init__(self, node: Node, component: str) -> None:
        self._node = node
        # Reliable with some depth: a record is one message per motion and none may be lost.
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.publisher = node.create_publisher(
            ExecutedTrajectory, ros_names.executed_trajectories_topic(component), qos
        )

    def now(self) -> Time:
        """The node's clock, as the record's ``started`` wants it."""
        return self._node.get_clock().now().to_msg()

    def publish(
        self,
        started: Time,
        joint_names: Sequence[str],
        planned_s: float,
        outcome: int,
        error_code: int,
        error_string: str,
    ) -> None:
        msg = ExecutedTrajectory()
        msg.header.stamp = self.now()
        msg.started = started
        msg.joint_names = list(joint_names)
        msg.planned_s = float(planned_s)
        msg.outcome = outcome
        msg.error_code = int(error_code)
        msg.error_string = error_string
        self.publisher.publish(msg)


__all__ = ["ABORTED", "CANCELED", "SUCCEEDED", "ExecutedTrajectoryPublisher", "planned_seconds"]
