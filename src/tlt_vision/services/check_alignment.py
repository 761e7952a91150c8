"""``CheckAlignment``: a member's held part, from the end pieces the EE cameras of the named
camera's arm see, in the world, against the mission's joint positions; the answered pose is the
tool pose that holds the part where it is seen (the ARS's convention)."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from rclpy.impl.rcutils_logger import RcutilsLogger

from tlt_common.mission.schema import Mission
from tlt_common.ros.stamps import set_stamp
from tlt_vision import inspection
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.camera_frames import NoFrame
from tlt_vision.frames import CameraRig, FrameUnavailable
from tlt_vision.node_config import VisionConfig, pose_of
from tlt_vision.part_inspection import STRUT_KINDS
from tlt_vision.pose.estimator import PoseEstimate
from tlt_vision.services.detector import Detector
from tlt_vision.services.frame_poser import FramePoser
from tlt_vision.services.frame_source import FrameSource
from tlt_vision.services.reports import pose_msg
from tlt_vision.services.world import SAME_PIECE_M, in_world, tower_origin

log = logging.getLogger("tlt.vision")


class CheckAlignmentHandler:
    """The ``CheckAlignment`` callback.

    Reads the mission's member and its joints where the tower stands (node.yaml ``site``), one
    fresh frame of each EE camera on the asked camera's arm, the camera and tool poses at their
    stamps (the arm's joint states; node.yaml ``tool``), and the certified end pieces near the
    member's places (``held_piece_gate``); :func:`inspection.held_part_alignment` decides, within
    the request's tolerances or the mission's. Answers ``aligned``, the errors and the tool pose
    that holds the part where it is seen, in the world frame. An unknown member, a kind without
    end pieces, a camera that is not on an end effector, no frame or pose from any camera, or an
    unexpected error is ``aligned`` false with the reason.
    """

    def __init__(
        self,
        *,
        frames: FrameSource,
        detector: Detector,
        poser: FramePoser,
        rig: CameraRig,
        mission: Mission,
        parts: Mapping[str, Any],
        tolerances: inspection.Tolerances,
        config: VisionConfig,
        clock: Callable[[], float],
        logger: RcutilsLogger,
    ) -> None:
        self.frames = frames
        self.detector = detector
        self.poser = poser
        self.rig = rig
        self.mission = mission
        self.parts = parts
        self.tol = tolerances
        self.config = config
        self.clock = clock
        self.logger = logger
        self.tool = pose_of(config.raw["tool"])

    def __call__(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            self.check(request, response)
        except Exception as exc:  # a service must answer: an unexpected error is a refusal
            log.exception("check_alignment failed")
            response.aligned, response.reason = False, f"vision error: {exc}"
        verdict = (
            f"aligned ({response.position_error * 1000:.1f} mm, {math.degrees(response.angle_error):.2f} deg)"
            if response.aligned
            else f"not aligned: {response.reason}"
        )
        self.logger.info(
            f"check_alignment {request.member_id} via {request.camera}: {verdict}"
            f" ({time.monotonic() - started:.1f} s wall)"
        )
        return response

    def check(self, request: Any, response: Any) -> Any:
        """Fill ``response`` for ``request`` (member, camera, tolerances) and return it."""
        deadline = self.frames.deadline()
        response.aligned = False
        response.position_error = response.angle_error = math.inf
        try:
            member = self.mission.member(request.member_id)
        except KeyError:
            response.reason = f"unknown member {request.member_id!r}"
            return response
        if member.kind not in (*STRUT_KINDS, "cross_frame"):
            response.reason = f"cannot check the alignment of a {member.kind}"
            return response
        tol = inspection.Tolerances(
            request.position_tolerance if request.position_tolerance > 0 else self.tol.position,
            request.angle_tolerance if request.angle_tolerance > 0 else self.tol.angle,
        )
        origin = tower_origin(self.config, self.mission, member.bay)
        joints = [origin + np.asarray(p, dtype=float) for _, p in member.joints]
        try:
            camera = self.frames.camera(request.camera)
            if camera not in self.rig.ee:
                raise NoFrame(f"camera {request.camera!r} is not an end-effector camera")
        except NoFrame as exc:
            response.reason = str(exc)
            return response
        return self._check_held_part(member, camera, joints, tol, deadline, response)

    def _check_held_part(
        self,
        member: Any,
        camera: str,
        joints: list[np.ndarray],
        tol: inspection.Tolerances,
        deadline: float,
        response: Any,
    ) -> Any:
        """CheckAlignment from the certified end pieces (a strut's end fittings, a cross frame's
        corner joints) that the EE cameras of ``camera``'s arm see
        (:func:`inspection.held_part_alignment`); a piece both see is one."""
        piece = "corner_joint" if member.kind == "cross_frame" else "end_fitting"
        pipeline = "bay" if member.kind == "cross_frame" else member.kind
        arm = self.rig.ee[camera].arm
        seen: list[PoseEstimate] = []
        problems: list[str] = []
        stamp = self.clock()
        tool: np.ndarray | None = None
        # Every camera's frame and pose first, then the poses (seconds each on a busy CPU): the
        # frames are of one moment, and the request's time is not spent before the last is taken.
        frames: list[tuple[CameraFrame, np.ndarray, np.ndarray]] = []  # frame, camera pose, as held
        counts: list[str] = []  # what each camera saw, for a check that fails
        uncertified: list[str] = []
        for cam in sorted(c.name for c in self.rig.ee.values() if c.arm == arm):
            try:
                frame = self.frames.grab(cam, self.detector.streams(), deadline)
                cam_pose = self.rig.camera_pose(cam, frame.stamp)
                at_frame = self.rig.tool_pose(cam, frame.stamp, self.tool)
                tool = at_frame if tool is None else tool
                # The held part moves with the tool: what a camera sees of it is put where the
                # tool held it when the first frame was taken, should the arm have moved between.
                frames.append((frame, cam_pose, tool @ np.linalg.inv(at_frame) @ cam_pose))
            except (NoFrame, FrameUnavailable) as exc:
                problems.append(f"{cam}: {exc}")
        places = inspection.expected_pieces(member.kind, joints, self.parts)
        for frame, cam_pose, held_pose in frames:
            stamp = frame.stamp
            try:
                detections = [d for d in self.detector.detect(frame) if d.object_class == piece]
            except NoFrame as exc:
                problems.append(f"{frame.camera}: {exc}")
                continue
            near = self.poser.near(detections, frame, cam_pose, places, piece)
            certified = 0
            prior = inspection.corner_joint_prior(places, cam_pose) if piece == "corner_joint" else None
            for o in self.poser.observe(pipeline, near, frame, prior):
                e = o.estimate
                if e is None or not e.certified:
                    uncertified.append(f"{frame.camera}: {o.reason or e.certificate.reason}")
                    continue
                certified += 1
                e = in_world(e, held_pose)
                if all(np.linalg.norm(m.translation - e.translation) >= SAME_PIECE_M for m in seen):
                    seen.append(e)
            counts.append(
                f"{frame.camera}: {len(detections)} segmented, {len(near)} near a place,"
                f" {certified} certified"
            )
        p = response.pose
        set_stamp(p.header.stamp, stamp)
        p.header.frame_id = self.config.raw["world_frame"]
        p.object_class = "cross_frame" if member.kind == "cross_frame" else "strut_tube"
        p.object_id = member.id
        if tool is None:
            response.reason = p.reason = "; ".join(problems)
            return response
        result = inspection.held_part_alignment(
            member.kind,
            places,
            [e.translation for e in seen],
            tool,
            tol,
            self.config.raw["held_piece_gate"],
        )
        response.aligned = bool(result.aligned)
        response.position_error, response.angle_error = result.position_error, result.angle_error
        seen_how = []
        if not result.aligned:
            off = [np.linalg.norm(np.asarray(places) - e.translation, axis=1).min() * 1000 for e in seen]
            seen_how = [
                f"{piece}s: {', '.join(counts)}",
                f"certified ones {', '.join(f'{d:.0f}' for d in off) or '-'} mm from a place",
                *uncertified,
            ]
        response.reason = "; ".join([r for r in (result.reason, *problems, *seen_how) if r])
        p.keypoint_groups_visible, p.keypoint_groups_required = result.matched, 2
        p.certified = result.held is not None
        if seen:
            p.chamfer_p90 = max(e.certificate.chamfer_p90 for e in seen)
            p.chamfer_threshold = min(e.certificate.chamfer_threshold for e in seen)
        if result.held is None:
            p.reason = response.reason
        else:
            p.pose = pose_msg(result.held)
        return response
