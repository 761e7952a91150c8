"""``InspectPart``: a strut (``vertical``, ``diagonal``) or a ``cross_frame`` held in front of a
camera, or ``rivet`` with member id ``<ars>/<gun>``: is a rivet in that EE gun."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from rclpy.impl.rcutils_logger import RcutilsLogger
from tlt_interfaces.msg import InspectionReport

from tlt_vision import inspection
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.camera_frames import NoFrame
from tlt_vision.detections import Detection
from tlt_vision.frames import CameraRig, FrameUnavailable
from tlt_vision.node_config import VisionConfig
from tlt_vision.part_inspection import STRUT_KINDS, PartInspector
from tlt_vision.self_filter import EeSelfFilter, drop_inside, off_own_ee, own_pixels
from tlt_vision.services.detector import Detector
from tlt_vision.services.frame_poser import FramePoser
from tlt_vision.services.frame_source import FrameSource
from tlt_vision.services.reports import failed_report, log_report, report_msg

log = logging.getLogger("tlt.vision")


class InspectPartHandler:
    """The ``InspectPart`` callback.

    A strut or cross frame: reads one fresh frame of the asked camera, its detections (down to the
    second look's score), and the arms' joint states to take their end effectors out of the depth;
    :meth:`PartInspector.inspect` decides. A rivet: reads one frame of the EE camera beside gun
    ``<ars>/<gun>`` (the asked camera must be on that arm) and passes on a certified rivet at the
    gun's muzzle (node.yaml ``rivet_in_gun_radius``); with none, the detections of any score at
    the muzzle joined into one (:meth:`_at_the_muzzle`). Answers an InspectionReport in the camera's
    frame, with every reason when it fails; an unknown kind or camera, no frame in time, a failed
    segmentation or an unexpected error is a failed report with that reason.
    """

    def __init__(
        self,
        *,
        frames: FrameSource,
        detector: Detector,
        poser: FramePoser,
        inspector: PartInspector,
        rig: CameraRig,
        ee_filter: EeSelfFilter,
        config: VisionConfig,
        clock: Callable[[], float],
        logger: RcutilsLogger,
    ) -> None:
        self.frames = frames
        self.detector = detector
        self.poser = poser
        self.inspector = inspector
        self.rig = rig
        self.ee_filter = ee_filter
        self.config = config
        self.clock = clock
        self.logger = logger

    def __call__(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            response.report = self.inspect(request.member_id, request.part_kind, request.camera)
        except Exception as exc:  # a service must answer: an unexpected error is a failed report
            log.exception("inspect_part failed")
            response.report = failed_report(
                request.member_id, request.part_kind, f"vision error: {exc}", self.clock()
            )
        what = f"inspect_part {request.part_kind} via {request.camera}"
        log_report(self.logger, what, response.report, started)
        return response

    def inspect(self, member_id: str, kind: str, camera_name: str) -> InspectionReport:
        """The report on part ``kind`` ``member_id`` seen by camera ``camera_name``."""
        deadline = self.frames.deadline()
        if kind == "rivet":
            return self._inspect_rivet(member_id, camera_name, deadline)
        if kind not in (*STRUT_KINDS, "cross_frame"):
            why = f"unknown part kind {kind!r} (vertical, diagonal, cross_frame, rivet)"
            return failed_report(member_id, kind, why, self.clock())
        try:
            camera = self.frames.camera(camera_name)
            frame = self.frames.grab(camera, self.detector.streams(), deadline)
            detections = self.detector.detect(frame, doubtful=True)
        except NoFrame as exc:
            return failed_report(member_id, kind, str(exc), self.clock())
        depth = self.without_own_ee(frame)
        detections = off_own_ee(detections, own_pixels(frame.get("depth"), depth), self.ee_filter.own_share)
        report, obs = self.inspector.inspect(
            member_id,
            kind,
            detections,
            depth,
            frame.intrinsics,
            frame.get("rgb"),
            self.detector.closer(frame),
            self.config.depth_noise_of(frame.camera, float(frame.camera_matrix[0, 0])),
        )
        self.poser.tell(frame, obs)
        ids = {id(o.estimate): o.object_id for o in obs if o.estimate is not None}
        return report_msg(report, frame.stamp, frame.frame_id, ids)

    def without_own_ee(self, frame: CameraFrame) -> np.ndarray | None:
        """The frame's depth with the arms' end effectors taken out (:mod:`tlt_vision.self_filter`):
        a presented part's fittings sit beside its EE's rivet guns. An arm whose joint states are
        missing or old stays in, with a warning (both, when the camera's own pose is unknown)."""
        depth = frame.get("depth")
        if depth is None or self.ee_filter.empty:
            return depth
        try:
            camera_pose = self.rig.camera_pose(frame.camera, frame.stamp)
        except FrameUnavailable as exc:
            self.logger.warning(f"end effectors left in {frame.camera}'s depth: {exc}")
            return depth
        placed = []
        for arm in self.rig.arms:
            try:
                ee = self.rig.end_effector(arm, frame.stamp)
            except FrameUnavailable as exc:
                self.logger.warning(f"{arm}'s end effector left in {frame.camera}'s depth: {exc}")
                continue
            placed += self.ee_filter.place(camera_pose, *ee)
        return drop_inside(depth, frame.intrinsics, placed, self.ee_filter.margin)[0]

    def _inspect_rivet(self, member_id: str, camera_name: str, deadline: float) -> InspectionReport:
        """Is a rivet in gun ``<ars>/<gun>``: a certified rivet pose at the gun's muzzle, seen by the
        EE camera beside that gun (the request's camera must be on that arm)."""
        ars, _, gun = member_id.partition("/")
        cams = [c for c in self.rig.ee.values() if c.arm == ars and c.gun_name == gun]
        if not cams:
            why = f"no EE camera watches rivet gun {member_id!r}"
            return failed_report(member_id, "rivet", why, self.clock())
        cam = cams[0]
        try:
            asked = self.frames.camera(camera_name)
            if asked not in self.rig.ee or self.rig.ee[asked].arm != ars:
                raise NoFrame(f"camera {camera_name!r} is not on {ars}'s end effector")
            frame = self.frames.grab(cam.name, self.detector.streams(), deadline)
            every = [d for d in self.detector.detect(frame, doubtful=True) if d.object_class == "rivet"]
        except NoFrame as exc:
            return failed_report(member_id, "rivet", str(exc), self.clock())
        muzzle = cam.gun_in_camera()
        radius = self.config.raw["rivet_in_gun_radius"]
        # Only a rivet near the muzzle can pass: the others in view (a feeder's, one already set
        # in the structure) would cost a pose each for nothing.
        seen = [d for d in every if d.score >= self.detector.min_score]
        detections = self.poser.within(seen, frame, np.eye(4), muzzle, "rivet", radius)
        elsewhere = len(seen) - len(detections)
        obs = self.poser.observe("rivet", detections, frame)
        certified = [o.estimate for o in obs if o.estimate is not None and o.estimate.certified]
        near = [e for e in certified if np.linalg.norm(e.translation - muzzle) <= radius]
        if not near:
            obs += self._at_the_muzzle(every, frame, muzzle, radius)
            certified = [o.estimate for o in obs if o.estimate is not None and o.estimate.certified]
            near = [e for e in certified if np.linalg.norm(e.translation - muzzle) <= radius]
        used = tuple(o.estimate for o in obs if o.estimate is not None)
        if near:
            report = inspection.InspectionReport(member_id, "rivet", True, (), used)
        else:
            why = [f"no rivet in the gun: none certified within {radius * 1000:.0f} mm of {gun}"]
            if elsewhere:
                why.append(f"{elsewhere} rivet(s) seen farther from the muzzle, not posed")
            why += [f"rivet: {o.reason}" for o in obs if o.estimate is None]
            why += [f"rivet: pose not certified ({e.certificate.reason})" for e in used if not e.certified]
            report = inspection.InspectionReport(member_id, "rivet", False, tuple(why), used)
        return report_msg(report, frame.stamp, frame.frame_id, {})

    def _at_the_muzzle(
        self, detections: list[Detection], frame: CameraFrame, muzzle: np.ndarray, radius: float
    ) -> list[inspection.Observation]:
        """The rivet detections at the muzzle at any score, joined into one and posed.

        A rivet in the gun sits at the edge of the D405's view, cut by the frame's border: Mask
        R-CNN scores what it sees of it low, or splits it. Where it must be is known and the gun
        holds one rivet, so the detections there are fragments of it; the certificate decides
        whether their cloud is a rivet at the muzzle.
        """
        there = self.poser.within(detections, frame, np.eye(4), muzzle, "rivet", radius)
        if not there:
            return []
        mask = np.logical_or.reduce([d.mask for d in there])
        joined = Detection("rivet", mask, max(d.score for d in there))
        return self.poser.observe("rivet", [joined], frame)
