"""``InspectBay``: the four corner joints of bay N seen by the inward ZEDs, placed in the world
through the transform tree and matched to the mission's joints."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from rclpy.impl.rcutils_logger import RcutilsLogger
from tlt_interfaces.msg import InspectionReport

from tlt_common.mission.schema import Mission
from tlt_vision import inspection
from tlt_vision.camera_frames import NoFrame
from tlt_vision.frames import CameraRig, FrameUnavailable
from tlt_vision.node_config import VisionConfig
from tlt_vision.services.detector import Detector
from tlt_vision.services.frame_poser import FramePoser
from tlt_vision.services.frame_source import FrameSource
from tlt_vision.services.reports import failed_report, log_report, report_msg
from tlt_vision.services.world import SAME_PIECE_M, in_world, tower_origin

log = logging.getLogger("tlt.vision")


class InspectBayHandler:
    """The ``InspectBay`` callback.

    Reads one fresh frame of each of node.yaml's ``bay_cameras``, the camera poses at their stamps
    (the lifter's joint states), and the mission's corner joints of the bay where the tower stands
    while it is built (node.yaml ``site``); a joint two cameras see is counted once, by its best
    fit. :func:`inspection.inspect_bay` decides, with ``bay_min_corner_joints`` and
    ``held_piece_gate``. Answers an InspectionReport in the world frame; a bay the mission lacks
    or an unexpected error is a failed report with the reason, and a failed bay's report names
    the cameras that gave no frame or pose.
    """

    def __init__(
        self,
        *,
        frames: FrameSource,
        detector: Detector,
        poser: FramePoser,
        rig: CameraRig,
        mission: Mission,
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
        self.tol = tolerances
        self.config = config
        self.clock = clock
        self.logger = logger

    def __call__(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            response.report = self.inspect(int(request.bay))
        except Exception as exc:  # a service must answer: an unexpected error is a failed report
            log.exception("inspect_bay failed")
            response.report = failed_report(f"bay{request.bay}", "bay", f"vision error: {exc}", self.clock())
        log_report(self.logger, "inspect_bay", response.report, started)
        return response

    def inspect(self, bay: int) -> InspectionReport:
        """The report on bay ``bay``'s corner joints."""
        deadline = self.frames.deadline()
        target = f"bay{bay}"
        try:
            origin = tower_origin(self.config, self.mission, bay)
            joints = inspection.bay_joints(self.mission, bay)
            expected = {k: origin + np.asarray(p) for k, p in joints.items()}
        except KeyError as exc:
            return failed_report(target, "bay", str(exc.args[0]), self.clock())
        world = self.config.raw["world_frame"]
        found: list[tuple[inspection.Observation, str]] = []
        problems: list[str] = []
        stamp = self.clock()
        for camera in self.config.raw["bay_cameras"]:
            try:
                frame = self.frames.grab(camera, self.detector.streams(), deadline)
                pose = self.rig.camera_pose(camera, frame.stamp)
                detections = [d for d in self.detector.detect(frame) if d.object_class == "corner_joint"]
            except (NoFrame, FrameUnavailable) as exc:
                problems.append(f"{camera}: {exc}")
                continue
            stamp = frame.stamp
            places = np.array(list(expected.values()))
            detections = self.poser.near(detections, frame, pose, places, "corner_joint")
            prior = inspection.corner_joint_prior(places, pose)
            for o in self.poser.observe("bay", detections, frame, prior):
                est = in_world(o.estimate, pose) if o.estimate is not None else None
                found.append((replace(o, estimate=est), o.object_id))
        merged: list[tuple[inspection.Observation, str]] = []
        for o, oid in sorted(
            found,
            key=lambda x: (
                x[0].estimate.certificate.chamfer_p90
                if x[0].estimate and x[0].estimate.certified
                else math.inf
            ),
        ):
            e = o.estimate
            if (
                e is not None
                and e.certified
                and any(
                    m.estimate is not None
                    and m.estimate.certified
                    and np.linalg.norm(m.estimate.translation - e.translation) < SAME_PIECE_M
                    for m, _ in merged
                )
            ):
                continue  # the same joint seen by the other camera
            merged.append((o, oid))
        report = inspection.inspect_bay(
            bay, expected, [o for o, _ in merged], self.tol, self.config.raw["held_piece_gate"],
            self.config.raw["bay_min_corner_joints"],
        )  # fmt: skip
        if not report.passed and problems:
            report = replace(report, reasons=(*report.reasons, *problems))
        ids = {id(o.estimate): oid for o, oid in merged if o.estimate is not None}
        return report_msg(report, stamp, world, ids)
