"""``LocateTag``: the dispenser's AprilTag (cv2.aruco, IPPE square) in the named camera's RGB; the
answered pose is the dispenser's frame in the world (the tag marks it)."""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
from rclpy.impl.rcutils_logger import RcutilsLogger

from tlt_common.geometry.transforms import invert, pose_matrix
from tlt_common.mission.schema import Mission
from tlt_common.mission.tag_mounts import tag_mount
from tlt_common.ros.stamps import set_stamp
from tlt_vision.apriltag import TagLocator, dispenser_tag_ids
from tlt_vision.camera_frames import NoFrame
from tlt_vision.frames import CameraRig, FrameUnavailable
from tlt_vision.node_config import VisionConfig
from tlt_vision.services.frame_source import FrameSource
from tlt_vision.services.reports import pose_msg

log = logging.getLogger("tlt.vision")


class LocateTagHandler:
    """The ``LocateTag`` callback.

    Reads one fresh RGB frame of the asked camera, its pose at the frame's stamp, the dispenser's
    tag id (its index among the mission's dispensers) and where the tag is mounted on it
    (node.yaml ``tag_mount``). Answers ``found``, the tag id, the reprojection error and the
    dispenser's frame in the world. An unknown dispenser or camera, no frame or camera pose in
    time, a tag not found, or an unexpected error is ``found`` false with the reason.
    """

    def __init__(
        self,
        *,
        frames: FrameSource,
        rig: CameraRig,
        tags: TagLocator,
        mission: Mission,
        config: VisionConfig,
        logger: RcutilsLogger,
    ) -> None:
        self.frames = frames
        self.rig = rig
        self.tags = tags
        self.mission = mission
        self.config = config
        self.logger = logger
        self.tag_ids = dispenser_tag_ids(list(mission.dispensers))

    def tag_mount(self, dispenser: str) -> np.ndarray:
        """The tag's frame in its dispenser's frame, where the twin mounts it (node.yaml ``tag_mount``)."""
        return tag_mount(self.config.raw["tag_mount"], self.mission, dispenser, self.tags.config.tag_side)

    def __call__(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            self.locate(request, response)
        except Exception as exc:  # a service must answer: an unexpected error is a tag not found
            log.exception("locate_tag failed")
            response.found, response.reason = False, f"vision error: {exc}"
        if response.found:
            p, q = response.pose.pose.position, response.pose.pose.orientation
            verdict = (
                f"at ({p.x:.4f}, {p.y:.4f}, {p.z:.4f}) m, quaternion ({q.x:.4f}, {q.y:.4f}, {q.z:.4f},"
                f" {q.w:.4f}), reprojection {response.reprojection_error:.2f} px"
            )
        else:
            verdict = f"not found: {response.reason}"
        self.logger.info(
            f"locate_tag {request.dispenser} via {request.camera}: {verdict}"
            f" ({time.monotonic() - started:.1f} s wall)"
        )
        return response

    def locate(self, request: Any, response: Any) -> Any:
        """Fill ``response`` for ``request`` (dispenser, camera) and return it."""
        deadline = self.frames.deadline()
        response.found = False
        if request.dispenser not in self.tag_ids:
            response.reason = f"unknown dispenser {request.dispenser!r}"
            return response
        tag_id = self.tag_ids[request.dispenser]
        response.tag_id = tag_id
        try:
            camera = self.frames.camera(request.camera)
            frame = self.frames.grab(camera, ("rgb",), deadline)
            cam_pose = self.rig.camera_pose(camera, frame.stamp)
        except (NoFrame, FrameUnavailable) as exc:
            response.reason = str(exc)
            return response
        result = self.tags.locate(frame.get("rgb"), tag_id, frame.camera_matrix)
        if result.pose is not None:
            response.reprojection_error = float(result.pose.reprojection_error)
        if not result.found:
            response.reason = result.reason
            return response
        tag = pose_matrix(result.pose.translation, result.pose.rotation)
        dispenser = cam_pose @ tag @ invert(self.tag_mount(request.dispenser))
        response.found = True
        set_stamp(response.pose.header.stamp, frame.stamp)
        response.pose.header.frame_id = self.config.raw["world_frame"]
        response.pose.pose = pose_msg(dispenser)
        return response
