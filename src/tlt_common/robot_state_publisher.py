"""``tlt-robot-state``: ``/tf`` of the EDU from its drivers' joint states and its URDF, where no
twin publishes it (the real EDU; docs/live-view.md). ROS 2's robot_state_publisher has no wheel.

The URDF comes from ``--urdf FILE`` (written by ``tlt twin urdf`` for the mission), which the node
also publishes latched on ``/robot_description``, or else from ``/robot_description`` itself. Every
fixed joint goes out once on ``/tf_static``; each ``sensor_msgs/JointState`` on the topics it is
given moves the joints it names, published on ``/tf`` as parent -> child at the message's stamp.
Driver joint names become URDF joint names by the first matching rule of ``JOINT_NAME_RULES``
(``ur_x_shoulder_pan_joint`` -> ``ars_x/shoulder_pan_joint``) or as they are
(``camera_mount_1``); a name that matches no URDF joint is ignored. The lifter, grippers and end
effectors report on their own state messages, not ``JointState``, and are not moved here.
"""

from __future__ import annotations

import argparse
import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rclpy.context import Context
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from tlt_common import ros_names
from tlt_common.geometry.transforms import rotvec_to_matrix, rpy_matrix
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.stamps import stamp_seconds
from tlt_common.ros.transform_messages import TF_QOS, TF_STATIC_QOS, transform_stamped

JOINT_NAME_RULES = ((re.compile(r"ur_(x|y)_(.+)"), r"ars_\1/\2"),)
DEFAULT_TOPICS = tuple(
    ros_names.joint_states_topic(c)
    for c in (ros_names.ur("ars_x"), ros_names.ur("ars_y"), ros_names.CAMERA_MOUNTS)
)


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint: ``kind`` fixed, revolute, continuous or prismatic; ``origin`` the child
    link's pose in the parent at zero (position, rotation)."""

    name: str
    kind: str
    parent: str
    child: str
    position: np.ndarray
    rotation: np.ndarray
    axis: np.ndarray

    def child_pose(self, q: float) -> tuple[np.ndarray, np.ndarray]:
        """The child link's pose in the parent at joint value ``q`` (rad or m)."""
        if self.kind == "prismatic":
            return self.position + self.rotation @ (self.axis * q), self.rotation
        if self.kind in ("revolute", "continuous"):
            return self.position, self.rotation @ rotvec_to_matrix((self.axis * q).tolist())
        return self.position, self.rotation


def _floats(text: str | None, default: str) -> np.ndarray:
    return np.array([float(v) for v in (text or default).split()])


def parse_urdf(text: str) -> dict[str, UrdfJoint]:
    """The joints of a URDF document by name. Raises ``ValueError`` for a document that is not one."""
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"not a URDF: {exc}") from None
    if robot.tag != "robot":
        raise ValueError(f"not a URDF: root element <{robot.tag}>")
    joints = {}
    for el in robot.findall("joint"):
        origin = el.find("origin")
        parent, child, axis = el.find("parent"), el.find("child"), el.find("axis")
        if parent is None or child is None:
            raise ValueError(f"joint {el.get('name')}: no parent or child")
        joints[el.get("name", "")] = UrdfJoint(
            name=el.get("name", ""),
            kind=el.get("type", "fixed"),
            parent=parent.get("link", ""),
            child=child.get("link", ""),
            position=_floats(origin.get("xyz") if origin is not None else None, "0 0 0"),
            rotation=rpy_matrix(_floats(origin.get("rpy") if origin is not None else None, "0 0 0").tolist()),
            axis=_floats(axis.get("xyz") if axis is not None else None, "1 0 0"),
        )
    return joints


def urdf_joint_name(driver_name: str) -> str:
    """A driver's joint name as the URDF names the joint (see the module docstring)."""
    for pattern, replacement in JOINT_NAME_RULES:
        if pattern.fullmatch(driver_name):
            return pattern.sub(replacement, driver_name)
    return driver_name


def static_message(joints: dict[str, UrdfJoint], t: float = 0.0) -> TFMessage:
    """Every fixed joint, for ``/tf_static``."""
    return TFMessage(
        transforms=[
            transform_stamped(j.parent, j.child, j.position, j.rotation, t)
            for j in joints.values()
            if j.kind == "fixed"
        ]
    )


def moving_message(joints: dict[str, UrdfJoint], state: JointState) -> TFMessage:
    """The joints ``state`` names (by :func:`urdf_joint_name`) that the URDF moves, at its stamp."""
    t = stamp_seconds(state.header.stamp)
    out = []
    for name, q in zip(state.name, state.position, strict=False):
        joint = joints.get(urdf_joint_name(name))
        if joint is not None and joint.kind != "fixed":
            out.append(transform_stamped(joint.parent, joint.child, *joint.child_pose(float(q)), t))
    return TFMessage(transforms=out)


class RobotStatePublisher(LeanNode):
    """Publishes ``/tf_static`` and ``/tf`` of a URDF from joint states (module docstring)."""

    def __init__(
        self,
        urdf: str | None = None,
        topics: tuple[str, ...] = DEFAULT_TOPICS,
        node_name: str = "robot_state",
        context: Context | None = None,
    ) -> None:
        super().__init__(node_name, context=context)
        self.joints: dict[str, UrdfJoint] = {}
        self._tf = self.create_publisher(TFMessage, ros_names.TF, TF_QOS)
        self._static = self.create_publisher(TFMessage, ros_names.TF_STATIC, TF_STATIC_QOS)
        if urdf is not None:
            self._set_urdf(urdf)
            description = self.create_publisher(String, ros_names.ROBOT_DESCRIPTION, TF_STATIC_QOS)
            description.publish(String(data=urdf))
        else:
            self.create_subscription(
                String, ros_names.ROBOT_DESCRIPTION, lambda m: self._set_urdf(m.data), TF_STATIC_QOS
            )
        for topic in topics:
            self.create_subscription(JointState, topic, self._on_joints, 10)

    def _set_urdf(self, text: str) -> None:
        try:
            self.joints = parse_urdf(text)
        except ValueError as exc:
            self.get_logger().error(f"robot description refused: {exc}")
            return
        self._static.publish(static_message(self.joints, self.get_clock().now().nanoseconds * 1e-9))

    def _on_joints(self, msg: JointState) -> None:
        out = moving_message(self.joints, msg)
        if out.transforms:
            self._tf.publish(out)


def main(argv: list[str] | None = None) -> int:
    """Publish until SIGINT/SIGTERM. Exit status 0, or 2 for a URDF file it cannot read."""
    import rclpy

    from tlt_common.ros.rosout_logging import init_rclpy
    from tlt_common.ros.spin_loop import spin_node
    from tlt_common.ros.stop_signals import stop_on_signals

    argv = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(prog="tlt-robot-state", description=__doc__.splitlines()[0])
    p.add_argument("--urdf", type=Path, help="URDF file (`tlt twin urdf -o`); default: /robot_description")
    p.add_argument("--topics", nargs="*", default=list(DEFAULT_TOPICS), help="sensor_msgs/JointState topics")
    args = p.parse_args(rclpy.utilities.remove_ros_args(["robot_state", *argv])[1:])
    urdf = None
    if args.urdf is not None:
        try:
            urdf = args.urdf.read_text()
            parse_urdf(urdf)
        except (OSError, ValueError) as exc:
            print(f"tlt-robot-state: {args.urdf}: {exc}", file=sys.stderr)
            return 2
    stop = stop_on_signals()
    init_rclpy(["robot_state", *argv], signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = RobotStatePublisher(urdf, tuple(args.topics))
    spin_node(node, lambda: bool(stop))
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = [
    "DEFAULT_TOPICS",
    "JOINT_NAME_RULES",
    "RobotStatePublisher",
    "UrdfJoint",
    "main",
    "moving_message",
    "parse_urdf",
    "static_message",
    "urdf_joint_name",
]
