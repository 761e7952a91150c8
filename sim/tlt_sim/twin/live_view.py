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
  shapes, each in its body's frame (``frame_locked``), so the tower's members move with /tf; sent
  again whenever what is shown changes (a rivet set appears).

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
from tlt_common.ros.stamps import split_seconds
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


def _quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Hamilton products of (w, x, y, z) quaternions."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=1,
    )


class MovingTransforms:
    """``/tf`` of ``scene``: every moving joint of ``tree`` (parent -> child) and every free body
    (``world`` -> body), computed for all at once from the simulation's body poses into messages
    made once (a /tf message is published many times a simulated second while a recorder listens)."""

    def __init__(self, scene: Scene, tree: list[urdf.Link]) -> None:
        m = scene.model
        self.scene = scene
        moving = [link for link in tree if link.joint_type != "fixed"]
        free = urdf.free_bodies(m)
        self.child = np.array([link.body for link in moving] + free, dtype=int)
        # The world body (0) stands for the free bodies' parent: its pose is the identity.
        self.parent = np.array(
            [int(m.body_parentid[link.body]) for link in moving] + [0] * len(free), dtype=int
        )
        frames = [(link.parent, link.name) for link in moving]
        frames += [(topics.WORLD_FRAME, m.body(b).name) for b in free]
        self.message = TFMessage(
            transforms=[transform_stamped(p, c, np.zeros(3), np.eye(3), 0.0) for p, c in frames]
        )

    def at(self, t: float) -> TFMessage:
        """The message with the poses the simulation has now, stamped ``t``."""
        d = self.scene.data
        pp, cp = d.xpos[self.parent], d.xpos[self.child]
        pr = d.xmat[self.parent].reshape(-1, 3, 3)
        pos = np.einsum("nji,nj->ni", pr, cp - pp)  # the parent's rotation transposed
        pq = d.xquat[self.parent] * np.array([1.0, -1.0, -1.0, -1.0])
        quat = _quat_multiply(pq, d.xquat[self.child])
        quat *= np.where(quat[:, :1] < 0, -1.0, 1.0)
        sec, nanosec = split_seconds(t)
        for msg, p, q in zip(self.message.transforms, pos.tolist(), quat.tolist(), strict=True):
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
            tr, rot = msg.transform.translation, msg.transform.rotation
            tr.x, tr.y, tr.z = p
            rot.w, rot.x, rot.y, rot.z = q
        return self.message


def free_body_markers(model: mujoco.MjModel) -> MarkerArray:
    """The visible shapes of the payload and every part, one marker each, in its body's frame (a
    namespace per body), after a DELETEALL of what the topic showed before."""
    out = MarkerArray(markers=[Marker(action=Marker.DELETEALL)])
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
        self.moving = MovingTransforms(scene, urdf.links(scene.model))
        self._next = 0.0
        self._tf = node.create_publisher(TFMessage, ros_names.TF, TF_QOS)
        self._static = node.create_publisher(TFMessage, ros_names.TF_STATIC, TF_STATIC_QOS)
        self._description = node.create_publisher(String, ros_names.ROBOT_DESCRIPTION, TF_STATIC_QOS)
        self._markers = node.create_publisher(MarkerArray, topics.MARKERS, TF_STATIC_QOS)
        velocities = {j: scene.max_velocity(j) for j in names.all_actuated_joints()}
        self._description.publish(String(data=urdf.urdf(scene.model, velocities)))
        self._static.publish(static_transforms(scene, scene.time))
        free = urdf.free_bodies(scene.model)
        self._free_geoms = np.concatenate(
            [
                np.arange(
                    scene.model.body_geomadr[b], scene.model.body_geomadr[b] + scene.model.body_geomnum[b]
                )
                for b in free
            ]
        ).astype(int)
        self._shown = b""
        self.publish_markers_if_changed()

    def publish_markers_if_changed(self) -> None:
        """Send the part markers again if the parts' shown geoms changed (a rivet was set)."""
        shown = self.scene.model.geom_group[self._free_geoms].tobytes()
        if shown != self._shown:
            self._shown = shown
            self._markers.publish(free_body_markers(self.scene.model))

    def publish_due(self, t: float) -> None:
        """Publish /tf when someone subscribes and it is due at sim time ``t``; the markers when
        what they show changed."""
        if t + 1e-9 < self._next:
            return
        self._next += self.period
        if self._next <= t + 1e-9:  # after a pause (nobody subscribed): a new grid from t
            self._next = t + self.period
        self.publish_markers_if_changed()
        if self._tf.get_subscription_count() > 0:
            self._tf.publish(self.moving.at(t))


__all__ = ["TOWER_FRAME", "LiveView", "MovingTransforms", "free_body_markers", "static_transforms"]
