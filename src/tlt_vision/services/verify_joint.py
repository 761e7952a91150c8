"""``VerifyJoint``: a riveted joint judged from one frame of an end-effector camera right after the
shot (:func:`tlt_vision.inspection.rivet_joint.judge_rivet_joint`), for the ARS's Verify Joint.

The caller says where the joint is from its own model (the mission's joint point where the tower
stands, the member's axis towards its tube, the side the gun fired from); this handler places the
hole on the fitting from the part drawings (``parts``: half a corner and half a fitting along the
axis from the joint, a fitting's radius out) and the camera's pose at the frame's stamp from the
arm's joint states. A frame that cannot settle the joint (out of view, hidden, without depth, no
frame at all, an unknown camera) answers ``cannot_judge`` with the reason: never a pass, and
never a verdict against the joint.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from rclpy.impl.rcutils_logger import RcutilsLogger

from tlt_vision.camera_frames import NoFrame
from tlt_vision.frames import CameraRig, FrameUnavailable
from tlt_vision.inspection.rivet_joint import (
    CANNOT_JUDGE,
    HoleView,
    RivetJointJudgement,
    RivetJointLimits,
    judge_rivet_joint,
)
from tlt_vision.services.detector import Detector
from tlt_vision.services.frame_source import FrameSource

log = logging.getLogger("tlt.vision")


def hole_in_world(
    joint: np.ndarray, along: np.ndarray, outward: np.ndarray, parts: Mapping[str, Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(hole, outward, along) in the world: where a seated head's centre lies on the fitting at
    ``joint`` of a member whose axis there is ``along`` (towards its tube), on the ``outward`` side
    (made square to the axis). ``ValueError`` for a zero or parallel pair of directions."""
    a = np.asarray(along, dtype=float)
    if not np.linalg.norm(a) > 0:
        raise ValueError("the member's axis is zero")
    a = a / np.linalg.norm(a)
    o = np.asarray(outward, dtype=float)
    o = o - (o @ a) * a
    if not np.linalg.norm(o) > 1e-9:
        raise ValueError("the gun's side is along the member's axis")
    o = o / np.linalg.norm(o)
    reach = parts["corner_size"] / 2 + parts["fitting_length"] / 2
    hole = np.asarray(joint, dtype=float) + reach * a + parts["fitting_radius"] * o
    return hole, o, a


def fill_response(
    response: Any, judgement: RivetJointJudgement, camera_pose: np.ndarray | None = None
) -> Any:
    """``response`` (VerifyJoint) from ``judgement``; the head moved into the world by the optical
    frame's ``camera_pose`` when both are there."""
    response.verdict, response.reason = judgement.verdict, judgement.reason
    response.height, response.along_offset = float(judgement.height_m), float(judgement.along_m)
    response.pixels = int(judgement.pixels)
    if judgement.head is not None and camera_pose is not None:
        head = camera_pose[:3, :3] @ judgement.head + camera_pose[:3, 3]
        response.head.x, response.head.y, response.head.z = (float(v) for v in head)
    return response


def _vector(msg: Any) -> np.ndarray:
    return np.array([msg.x, msg.y, msg.z], dtype=float)


class VerifyJointHandler:
    """The ``VerifyJoint`` callback (see the module docstring).

    Reads one fresh frame of the asked EE camera (its depth and what the segmenter reads), the
    segmenter's ``rivet`` detections at the node's score, the camera's pose at the frame's stamp,
    the parts' drawings (``parts``) and the judgement's ``limits`` (the rivet head's radius from
    the drawings, the rest :class:`RivetJointLimits`' own).
    """

    def __init__(
        self,
        *,
        frames: FrameSource,
        detector: Detector,
        rig: CameraRig,
        parts: Mapping[str, Any],
        limits: RivetJointLimits,
        clock: Callable[[], float],
        logger: RcutilsLogger,
    ) -> None:
        self.frames = frames
        self.detector = detector
        self.rig = rig
        self.parts = parts
        self.limits = limits
        self.clock = clock
        self.logger = logger

    def __call__(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            self.verify(request, response)
        except Exception as exc:  # a service must answer: an unexpected error judges nothing
            log.exception("verify_joint failed")
            fill_response(response, RivetJointJudgement(CANNOT_JUDGE, f"vision error: {exc}"))
        self.logger.info(
            f"verify_joint {request.joint_id} via {request.camera}: {response.verdict}"
            f" ({response.reason}; {time.monotonic() - started:.1f} s wall)"
        )
        return response

    def verify(self, request: Any, response: Any) -> Any:
        """Fill ``response`` for ``request`` and return it."""
        deadline = self.frames.deadline()
        try:
            hole, outward, along = hole_in_world(
                _vector(request.joint), _vector(request.along), _vector(request.outward), self.parts
            )
        except ValueError as exc:
            return fill_response(response, RivetJointJudgement(CANNOT_JUDGE, f"no hole to look at: {exc}"))
        try:
            camera = self.frames.camera(request.camera)
            if camera not in self.rig.ee:
                raise NoFrame(f"camera {request.camera!r} is not an end-effector camera")
            frame = self.frames.grab(camera, self.detector.streams(), deadline)
            pose = self.rig.camera_pose(camera, frame.stamp)
            detections = [d for d in self.detector.detect(frame) if d.object_class == "rivet"]
        except (NoFrame, FrameUnavailable) as exc:
            return fill_response(response, RivetJointJudgement(CANNOT_JUDGE, str(exc)))
        depth = frame.get("depth")
        if depth is None:
            return fill_response(response, RivetJointJudgement(CANNOT_JUDGE, f"{camera}: no depth"))
        view = HoleView.from_world(hole, outward, along, pose[:3, 3], pose[:3, :3])
        judgement = judge_rivet_joint(detections, depth, frame.intrinsics, view, self.limits)
        return fill_response(response, judgement, pose)


__all__ = ["VerifyJointHandler", "fill_response", "hole_in_world"]
