"""What a 3D viewer needs from the twin: the EDU's robot description, its transform tree and the
shapes of the payload and the parts (docs/live-view.md).

Topics (names in :mod:`tlt_common.ros_names` and :mod:`tlt_sim.twin.topics`):

* ``/robot_description`` (``std_msgs/String``, latched): the URDF of the running model
  (:mod:`tlt_sim.model.urdf`), its camera mounts as the twin has them;
* ``/tf_static`` (``tf2_msgs/TFMessage``, latched, one message): every fixed joint of the URDF (the
  lifter frame, the pedestals, the EE bodies, the dispensers, each camera's optical frame) and
  ``payload`` -> ``tower`` (the mission's joint coordinates, as ``/twin/ground_truth`` names it);
* ``/tf`` (``tf2_msgs/TFMessage``, while subscribed, ``tf_rate_hz`` per simulated second): every
  moving joint as its parent -> child transform (lifter carriages, grippers, camera mounts, arm
  links, EE width and jaws) and ``world`` -> each free body (``payload``, ``part/<dispenser>/<i>``),
  all of one instant, stamped with sim time;
* ``/twin/markers`` (``visualization_msgs/MarkerArray``, latched): the payload's and every part's
  shapes, each in its body's frame (``frame_locked``), so the tower's members move with /tf.

Runs on the simulation thread, like :mod:`tlt_sim.twin.ros_streams`.
"""

from __future__ import annotations

import mujoco
import numpy as np
from rclpy.node import Node
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from tlt_common import ros_names
from tlt_common.geometry.transforms import rotation_to_quaternion
from tlt_common.ros.transform_messages import TF_QOS, TF_STATIC_QOS, transform_stamped
from tlt_sim.model import names, urdf
from tlt_sim.model.scene import Scene
from tlt_sim.twin import topics

TOWER_FRAME = "tower"
_MARKER_TYPES = {"box": Marker.CUBE, "sphere": Marker.SPHERE, "cylinder": Marker.CYLINDER}


def static_transforms(scene: Scene, t: float = 0.0) -> TFMessage:
    """Every fixed joint of the EDU's URDF, and the tower frame on the payload."""
    fixed = [link for link in urdf.links(scene.model) if link.joint_type == "fixed"]
    out = [transform_stamped(link.parent, link.name, *link.origin, t) for link in fixed]
    out.append(transform_stamped("payload", TOWER_FRAME, np.zeros(3), np.eye(3), t))
    return TFMessage(transforms=out)


def moving_transforms(scene: Scene, tree: list[urdf.Link], t: float) -> TFMessage:
    """The EDU's moving joints and the free bodies as the simulation has them now."""
    m, d = scene.model, scene.data
    out = [
        transform_stamped(parent, child, p, r, t)
        for child, (parent, p, r) in urdf.moving_poses(m, d, tree).items()
    ]
    out += [
        transform_stamped(topics.WORLD_FRAME, b, p, r, t) for b, (p, r) in urdf.free_body_poses(m, d).items()
    ]
    return TFMessage(transforms=out)


def free_body_markers(model: mujoco.MjModel) -> MarkerArray:
    """The visible shapes of the payload and every part, one marker each, in its body's frame."""
    out = MarkerArray()
    for b in urdf.free_bodies(model):
        body = model.body(b).name
        n = 0
        for g in urdf.visible_geoms(model, b):
            rgba = model.geom_rgba[g] if model.geom_matid[g] < 0 else model.mat_rgba[model.geom_matid[g]]
            for kind, size, pos, rot in urdf.geom_shapes(model, g):
                marker = Marker(ns=body, id=n, type=_MARKER_TYPES[kind], action=Marker.ADD, frame_locked=True)
                marker.header.frame_id = body
                marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = (
                    float(v) for v in pos
                )
                q = marker.pose.orientation
                q.x, q.y, q.z, q.w = rotation_to_quaternion(rot)
                marker.scale.x, marker.scale.y, marker.scale.z = (float(v) for v in size)
                marker.color.r, marker.color.g, marker.color.b, marker.color.a = (float(v) for v in rgba)
                out.markers.append(marker)
                n += 1
    return out


class LiveView:
    """Publishes the robot description, the transform tree and the part markers of ``scene``."""

    def __init__(self, node: Node, scene: Scene, tf_rate_hz: float) -> None:
        self.scene = scene
        self.period = 1.0 / tf_rate_hz
        self.tree = urdf.links(scene.model)
        self._next = 0.0
        self._tf = node.create_publisher(TFMessage, ros_names.TF, TF_QOS)
        self._static = node.create_publisher(TFMessage, ros_names.TF_STATIC, TF_STATIC_QOS)
        self._description = node.create_publisher(String, ros_names.ROBOT_DESCRIPTION, TF_STATIC_QOS)
        self._markers = node.create_publisher(MarkerArray, topics.MARKERS, TF_STATIC_QOS)
        velocities = {j: scene.max_velocity(j) for j in names.all_actuated_joints()}
        self._description.publish(String(data=urdf.urdf(scene.model, velocities)))
        self._static.publish(static_transforms(scene, scene.time))
        self._markers.publish(free_body_markers(scene.model))

    def publish_due(self, t: float) -> None:
        """Publish /tf when someone subscribes and it is due at sim time ``t``."""
        if self._tf.get_subscription_count() == 0 or t + 1e-9 < self._next:
            return
        self._next += self.period
        if self._next <= t + 1e-9:  # after a pause (nobody subscribed): a new grid from t
            self._next = t + self.period
        self._tf.publish(moving_transforms(self.scene, self.tree, t))


__all__ = ["TOWER_FRAME", "LiveView", "free_body_markers", "moving_transforms", "static_transforms"]
