"""The certified poses each request found, published for people and tools to see (docs/live-view.md).

Every certified pose of a frame becomes a frame of the transform tree on ``/tf``, child of the
camera's optical frame (the image's ``frame_id``), named for the camera and the part:
``vision/<camera>/<class>_<n>`` (``vision/zed_1/end_fitting_0``), ``n`` counting that class's
certified poses in the frame. And a marker set on ``VISION_MARKERS`` in the camera's frame: the
corrected keypoints of each pose and its name, one namespace per camera, replacing what that
camera showed before (so a viewer shows each camera's latest answer). Stamps are the frame's.
Uncertified poses are left out: they are what vision could not vouch for.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

from geometry_msgs.msg import Point
from rclpy.node import Node
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from tlt_common import ros_names
from tlt_common.ros.stamps import set_stamp
from tlt_common.ros.transform_messages import TF_QOS, transform_stamped
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.inspection.report import Observation
from tlt_vision.pose.estimator import PoseEstimate

KEYPOINT_DIAMETER = 0.012  # m
LABEL_HEIGHT = 0.03  # m
CERTIFIED_COLOUR = (0.1, 0.9, 0.2, 1.0)


def certified(observations: Sequence[Observation]) -> list[PoseEstimate]:
    """The certified estimates of ``observations``, in order."""
    return [o.estimate for o in observations if o.estimate is not None and o.estimate.certified]


def pose_frames(frame: CameraFrame, estimates: Sequence[PoseEstimate]) -> list[str]:
    """Frame id of each estimate: ``vision/<camera>/<class>_<n>``."""
    counts: dict[str, int] = {}
    out = []
    for e in estimates:
        n = counts.get(e.object_class, 0)
        counts[e.object_class] = n + 1
        out.append(f"vision/{frame.camera}/{e.object_class}_{n}")
    return out


def pose_transforms(frame: CameraFrame, estimates: Sequence[PoseEstimate]) -> TFMessage:
    """Each estimate as the transform camera optical frame -> its pose frame, at the frame's time."""
    names = pose_frames(frame, estimates)
    return TFMessage(
        transforms=[
            transform_stamped(frame.frame_id, name, e.translation, e.rotation, frame.stamp)
            for name, e in zip(names, estimates, strict=True)
        ]
    )


def pose_markers(frame: CameraFrame, estimates: Sequence[PoseEstimate], shown_before: int = 0) -> MarkerArray:
    """Keypoints and a label per estimate in the camera's frame (namespace ``vision/<camera>``),
    and a deletion of every marker id up to ``shown_before`` that this set does not reuse."""
    out = MarkerArray()
    ns = f"vision/{frame.camera}"

    def marker(marker_id: int, kind: int) -> Marker:
        m = Marker(ns=ns, id=marker_id, type=kind, action=Marker.ADD)
        m.header.frame_id = frame.frame_id
        set_stamp(m.header.stamp, frame.stamp)
        m.pose.orientation.w = 1.0
        m.color.r, m.color.g, m.color.b, m.color.a = CERTIFIED_COLOUR
        return m

    for i, (name, e) in enumerate(zip(pose_frames(frame, estimates), estimates, strict=True)):
        points = marker(2 * i, Marker.SPHERE_LIST)
        points.scale.x = points.scale.y = points.scale.z = KEYPOINT_DIAMETER
        points.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in e.keypoints]
        label = marker(2 * i + 1, Marker.TEXT_VIEW_FACING)
        label.scale.z = LABEL_HEIGHT
        label.text = name.rsplit("/", 1)[-1]
        label.pose.position.x, label.pose.position.y, label.pose.position.z = (
            float(v) for v in e.translation
        )
        out.markers += [points, label]
    for stale in range(len(out.markers), shown_before):
        gone = Marker(ns=ns, id=stale, action=Marker.DELETE)
        gone.header.frame_id = frame.frame_id
        out.markers.append(gone)
    return out


class PoseBroadcaster:
    """Publishes the certified poses of each posed frame on ``/tf`` and ``VISION_MARKERS``.
    Called from the services' threads, so what each camera showed last is kept under a lock."""

    def __init__(self, node: Node) -> None:
        self._tf = node.create_publisher(TFMessage, ros_names.TF, TF_QOS)
        self._markers = node.create_publisher(MarkerArray, ros_names.VISION_MARKERS, 10)
        self._shown: dict[str, int] = {}
        self._lock = threading.Lock()

    def __call__(self, frame: CameraFrame, observations: Sequence[Observation]) -> None:
        estimates = certified(observations)
        with self._lock:
            markers = pose_markers(frame, estimates, self._shown.get(frame.camera, 0))
            self._shown[frame.camera] = 2 * len(estimates)
        if estimates:
            self._tf.publish(pose_transforms(frame, estimates))
        if markers.markers:
            self._markers.publish(markers)


__all__ = ["PoseBroadcaster", "certified", "pose_frames", "pose_markers", "pose_transforms"]
