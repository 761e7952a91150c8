"""Certified poses into /tf and markers (tlt_vision.pose_broadcast): named for the camera and the
part, in the camera's optical frame, uncertified ones left out, stale markers deleted."""

from __future__ import annotations

import numpy as np
from visualization_msgs.msg import Marker

from tlt_common.geometry.transforms import quaternion_to_rotation, rpy_matrix
from tlt_common.ros.stamps import stamp_seconds
from tlt_vision import pose_broadcast
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.inspection.report import Observation
from tlt_vision.pointcloud import Intrinsics
from tlt_vision.pose.certificate import Certificate
from tlt_vision.pose.estimator import PoseEstimate

FRAME = CameraFrame(
    camera="zed_1",
    stamp=42.5,
    frame_id="zed_1_optical",
    intrinsics=Intrinsics(500.0, 500.0, 320.0, 240.0),
    camera_matrix=np.eye(3),
)


def _estimate(object_class: str, position, certified: bool = True) -> PoseEstimate:
    certificate = Certificate(certified, 0.001, 0.004, 3, 2, ("a", "b", "c"), "" if certified else "too far")
    return PoseEstimate(
        object_class=object_class,
        model_name=object_class,
        rotation=rpy_matrix([0.1, 0.2, 0.3]),
        translation=np.asarray(position, dtype=float),
        keypoints=np.asarray(position, dtype=float) + np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.05]]),
        certificate=certificate,
        num_points=500,
        objective=1e-6,
    )


OBSERVATIONS = [
    Observation("end_fitting", _estimate("end_fitting", [0.1, 0.0, 0.9])),
    Observation("strut_tube", _estimate("strut_tube", [0.0, 0.0, 0.9], certified=False)),
    Observation("strut_tube", None, reason="too few points"),
    Observation("end_fitting", _estimate("end_fitting", [-0.1, 0.0, 0.9])),
    Observation("strut_tube", _estimate("strut_tube", [0.0, 0.02, 0.9])),
]


def test_certified_poses_become_frames_of_the_camera_named_for_camera_and_part():
    estimates = pose_broadcast.certified(OBSERVATIONS)
    msg = pose_broadcast.pose_transforms(FRAME, estimates)
    assert [t.child_frame_id for t in msg.transforms] == [
        "vision/zed_1/end_fitting_0",
        "vision/zed_1/end_fitting_1",
        "vision/zed_1/strut_tube_0",
    ]
    for t, e in zip(msg.transforms, estimates, strict=True):
        assert t.header.frame_id == "zed_1_optical" and stamp_seconds(t.header.stamp) == 42.5
        p, q = t.transform.translation, t.transform.rotation
        assert np.allclose([p.x, p.y, p.z], e.translation)
        assert np.allclose(quaternion_to_rotation([q.x, q.y, q.z, q.w]), e.rotation)


def test_markers_show_each_certified_pose_and_delete_what_the_camera_showed_before():
    estimates = pose_broadcast.certified(OBSERVATIONS)
    shown = pose_broadcast.pose_markers(FRAME, estimates).markers
    assert len(shown) == 6 and {m.ns for m in shown} == {"vision/zed_1"}
    assert all(m.header.frame_id == "zed_1_optical" and m.action == Marker.ADD for m in shown)
    assert [m.text for m in shown if m.type == Marker.TEXT_VIEW_FACING] == [
        "end_fitting_0",
        "end_fitting_1",
        "strut_tube_0",
    ]
    assert [len(m.points) for m in shown if m.type == Marker.SPHERE_LIST] == [2, 2, 2]
    fewer = pose_broadcast.pose_markers(FRAME, estimates[:1], shown_before=len(shown)).markers
    assert [m.action for m in fewer] == [Marker.ADD] * 2 + [Marker.DELETE] * 4
    assert [m.id for m in fewer if m.action == Marker.DELETE] == [2, 3, 4, 5]
