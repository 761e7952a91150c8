"""Poses into the standard transform messages (``geometry_msgs/TransformStamped``,
``tf2_msgs/TFMessage``) and the QoS that ``/tf`` and ``/tf_static`` use in ROS 2.

``/tf`` carries transforms that change (volatile, a deep queue); ``/tf_static`` carries the fixed
ones, all in one latched message, so a listener that joins late still gets every one of them
(tf2_ros's static broadcaster does the same). Frame ids never start with ``/`` (tf2 refuses them).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from tlt_common.geometry.transforms import rotation_to_quaternion
from tlt_common.ros.stamps import set_stamp

TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
TF_STATIC_QOS = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    history=HistoryPolicy.KEEP_LAST,
)


def frame_id(name: str) -> str:
    """``name`` as a tf2 frame id: without a leading ``/``. Raises ``ValueError`` for an empty one."""
    out = name.lstrip("/")
    if not out:
        raise ValueError(f"{name!r} is not a frame id")
    return out


def transform_stamped(
    parent: str, child: str, position: Iterable[float], rotation: np.ndarray, t: float
) -> TransformStamped:
    """The pose of frame ``child`` in frame ``parent`` (``position``, a 3x3 ``rotation``) at ``t`` s."""
    msg = TransformStamped()
    set_stamp(msg.header.stamp, t)
    msg.header.frame_id = frame_id(parent)
    msg.child_frame_id = frame_id(child)
    x, y, z = (float(v) for v in position)
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = x, y, z
    q = msg.transform.rotation
    q.x, q.y, q.z, q.w = rotation_to_quaternion(np.asarray(rotation, dtype=float))
    return msg


def tf_message(parent: str, poses: dict[str, tuple[np.ndarray, np.ndarray]], t: float) -> TFMessage:
    """One ``TFMessage`` of every ``child -> (position, rotation)`` of ``poses`` in ``parent``."""
    return TFMessage(transforms=[transform_stamped(parent, c, p, r, t) for c, (p, r) in poses.items()])


__all__ = ["TF_QOS", "TF_STATIC_QOS", "frame_id", "tf_message", "transform_stamped"]
