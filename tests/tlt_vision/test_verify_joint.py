"""The VerifyJoint service's handler: where it puts the hole from the caller's joint and the part
drawings, and what it answers for a frame with a seated head, a proud one, none, and for a
request it cannot judge (no frame, a camera not on an end effector, no depth, directions that
say nothing). The frame is made by hand: a fitting's face 0.30 m in front of the camera and a
rivet head's disc on it, its mask standing in for the segmenter's (the twin renders are
test_rivet_joint.py's)."""

from __future__ import annotations

import logging
from types import SimpleNamespace

import numpy as np
import pytest
from tlt_interfaces.srv import VerifyJoint

from tlt_vision.camera_frame import CameraFrame
from tlt_vision.camera_frames import NoFrame
from tlt_vision.detections import Detection
from tlt_vision.inspection.rivet_joint import RivetJointLimits
from tlt_vision.pointcloud import Intrinsics
from tlt_vision.services.verify_joint import VerifyJointHandler, hole_in_world

PARTS = {"corner_size": 0.05, "fitting_length": 0.05, "fitting_radius": 0.02}
K = Intrinsics(300.0, 300.0, 160.0, 120.0)
CAMERA = "ars_x/d405_a"
# The camera's optical frame is the world's; the member runs along x, the gun fired from -z (the
# camera's side), so the hole is 5 cm along and 2 cm out from the joint: straight ahead at 0.30 m.
JOINT, ALONG, OUTWARD = np.array([-0.05, 0.0, 0.32]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])


def _frame(head_depth: float | None, *, depth: bool = True) -> tuple[CameraFrame, list[Detection]]:
    v, u = np.mgrid[0:240, 0:320]
    image = np.full((240, 320), 0.30)
    disc = np.hypot(u - 160, v - 120) <= 5.5
    detections = []
    if head_depth is not None:
        image[disc] = head_depth
        detections.append(Detection("rivet", disc))
    detections.append(Detection("end_fitting", np.hypot(u - 160, v - 120) <= 30))
    images = {"depth": image} if depth else {}
    k = np.array([[K.fx, 0, K.cx], [0, K.fy, K.cy], [0, 0, 1]])
    return CameraFrame(CAMERA, 1.0, "d405_a_optical", K, k, images), detections


class _Frames:
    def __init__(self, frame: CameraFrame | None) -> None:
        self.frame = frame

    def camera(self, name: str) -> str:
        if name not in (CAMERA, "zed_1"):
            raise NoFrame(f"unknown camera {name!r}")
        return name

    def deadline(self) -> float:
        return float("inf")

    def grab(self, camera, streams, deadline) -> CameraFrame:
        if self.frame is None:
            raise NoFrame(f"no frame from {camera} in time")
        return self.frame


class _Detector:
    def __init__(self, detections: list[Detection]) -> None:
        self.detections = detections

    def streams(self) -> tuple[str, ...]:
        return ("depth", "labels")

    def detect(self, frame, doubtful=False) -> list[Detection]:
        return self.detections


def _handler(frame: CameraFrame | None, detections: list[Detection]) -> VerifyJointHandler:
    rig = SimpleNamespace(ee={CAMERA: None}, camera_pose=lambda camera, at: np.eye(4))
    return VerifyJointHandler(
        frames=_Frames(frame),
        detector=_Detector(detections),
        rig=rig,
        parts=PARTS,
        limits=RivetJointLimits(head_radius=0.006),
        clock=lambda: 1.0,
        logger=logging.getLogger("test"),
    )


def _ask(handler: VerifyJointHandler, camera: str = CAMERA, along=ALONG, outward=OUTWARD):
    request = VerifyJoint.Request(joint_id="bay1/vertical/x0_y0@bay1/x0_y0", camera=camera)
    request.joint.x, request.joint.y, request.joint.z = JOINT
    request.along.x, request.along.y, request.along.z = along
    request.outward.x, request.outward.y, request.outward.z = outward
    return handler(request, VerifyJoint.Response())


def test_the_hole_lies_half_a_corner_and_half_a_fitting_along_and_a_fitting_out():
    hole, out, along = hole_in_world(JOINT, 2 * ALONG, OUTWARD + 0.3 * ALONG, PARTS)
    np.testing.assert_allclose(hole, [0.0, 0.0, 0.30])
    np.testing.assert_allclose(out, OUTWARD)
    np.testing.assert_allclose(along, ALONG)
    with pytest.raises(ValueError, match="along the member"):
        hole_in_world(JOINT, ALONG, ALONG, PARTS)
    with pytest.raises(ValueError, match="zero"):
        hole_in_world(JOINT, np.zeros(3), OUTWARD, PARTS)


def test_a_seated_head_is_good_with_its_figures_and_its_place_in_the_world():
    response = _ask(_handler(*_frame(0.297)))
    assert response.verdict == VerifyJoint.Response.GOOD, response.reason
    assert abs(response.height) < 0.002 and abs(response.along_offset) < 0.002
    assert response.pixels > 50
    assert response.head.z == pytest.approx(0.297, abs=0.002)


def test_a_proud_head_is_unseated_and_a_missing_one_no_head():
    proud = _ask(_handler(*_frame(0.292)))
    assert proud.verdict == VerifyJoint.Response.UNSEATED, proud.reason
    assert proud.height == pytest.approx(0.005, abs=0.001)
    missing = _ask(_handler(*_frame(None)))
    assert missing.verdict == VerifyJoint.Response.NO_HEAD, missing.reason


def test_what_cannot_be_judged_says_why_and_never_passes():
    frame, detections = _frame(0.297)
    answers = {
        "no frame": _ask(_handler(None, detections)),
        "not an EE camera": _ask(_handler(frame, detections), camera="zed_1"),
        "unknown camera": _ask(_handler(frame, detections), camera="nowhere"),
        "no depth": _ask(_handler(*_frame(0.297, depth=False))),
        "gun along the member": _ask(_handler(frame, detections), outward=ALONG),
    }
    for case, response in answers.items():
        assert response.verdict == VerifyJoint.Response.CANNOT_JUDGE, case
        assert response.reason, case
    assert "in time" in answers["no frame"].reason
    assert "not an end-effector camera" in answers["not an EE camera"].reason
    assert "no depth" in answers["no depth"].reason


def test_an_unexpected_error_is_an_answer_that_cannot_judge():
    frame, _ = _frame(0.297)
    handler = _handler(frame, [])
    handler.detector = None  # any error inside the judgement
    response = _ask(handler)
    assert response.verdict == VerifyJoint.Response.CANNOT_JUDGE
    assert response.reason.startswith("vision error:")
