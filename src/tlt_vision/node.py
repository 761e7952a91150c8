"""``tlt-vision``: the vision node serving part and bay inspection, alignment and dispenser tags.

Services (names from :mod:`tlt_common.ros_names`; paper §V.E):

* ``VISION_INSPECT_PART`` (``InspectPart``): a strut (``vertical``, ``diagonal``) or a
  ``cross_frame`` held in front of a lifter ZED, or ``rivet`` with member id ``<ars>/<gun>``: is a
  rivet in that EE gun (seen by the D405 beside it). The report passes or fails with every reason.
* ``VISION_INSPECT_BAY`` (``InspectBay``): the four corner joints of bay N seen by the inward ZEDs,
  placed in the world through the transform tree and matched to the mission's joints.
* ``VISION_CHECK_ALIGNMENT`` (``CheckAlignment``): the member's held part, from the end pieces the
  EE cameras of the named camera's arm see, in the world, against the mission's joint positions;
  the answered pose is the tool pose that holds the part where it is seen (the ARS's convention).
* ``VISION_LOCATE_TAG`` (``LocateTag``): the dispenser's AprilTag (cv2.aruco, IPPE square) in the
  named camera's RGB; the answered pose is the dispenser's frame in the world (the tag marks it).

Each request takes one fresh frame of its camera (:mod:`tlt_vision.camera_frames`: subscribed
only while it waits, at most ``timeouts.frame_s``), segments it (``segmentation.source``: the
twin's labels or Mask R-CNN), turns the part's instances into point clouds and certified C-3PO
poses (:mod:`tlt_vision.pipeline`), and decides (:mod:`tlt_vision.inspection`). Camera poses come
from :mod:`tlt_vision.frames`. Every failure (unknown camera, no frame in time, part not in view,
no certified pose, no joint state) is an answer with the reason, never an exception or a hang.
Each service has its own callback group, so one slow request does not hold the others' replies.
The node runs on ROS time (``--ros-args -p use_sim_time:=true`` under the twin).

Weights files are checked when the node is built: a missing or mismatched file stops it there,
with the path and the expected shape named.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import Pose
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from tlt_interfaces.msg import CertifiedPose, EndEffectorState, InspectionReport
from tlt_interfaces.srv import CheckAlignment, InspectBay, InspectPart, LocateTag

from tlt_common import ros_names
from tlt_common.config_schema import ConfigError
from tlt_common.direct_executor import DirectMultiThreadedExecutor, QuickCallbackGroup
from tlt_common.executor_stop import stop_executor
from tlt_common.geometry.transforms import invert, pose_matrix, rotation_to_quaternion
from tlt_common.interpreter_lock import share_the_interpreter_quickly
from tlt_common.lean_node import LeanNode
from tlt_common.mission.schema import Mission, load_mission
from tlt_common.spin_loop import spin
from tlt_common.stamps import set_stamp
from tlt_common.stop_signals import stop_on_signals
from tlt_vision import inspection
from tlt_vision.apriltag import TagConfig, TagLocator, dispenser_tag_ids
from tlt_vision.camera_frames import CameraFrame, FrameGrabber, NoFrame, SegmentationLabels
from tlt_vision.frames import CameraRig, FrameUnavailable
from tlt_vision.node_config import DEFAULT_CONFIG, VisionConfig, load_config, pose_of
from tlt_vision.part_inspection import STRUT_KINDS, LookCloser, PartInspector
from tlt_vision.pipeline import Detection, detections_near
from tlt_vision.pose.estimator import PoseEstimate
from tlt_vision.segmentation_source import MaskRcnnSegmenter, TwinLabels
from tlt_vision.self_filter import EeSelfFilter, drop_inside, off_own_ee, own_pixels
from tlt_vision.tag_mounts import tag_mount
from tlt_vision.weights import WeightsError

log = logging.getLogger("tlt.vision")
BAY_DUPLICATE_M = 0.02  # pieces seen by two cameras closer than this are one piece


def pose_msg(t: np.ndarray) -> Pose:
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in t[:3, 3])
    x, y, z, w = rotation_to_quaternion(t[:3, :3])
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = x, y, z, w
    return p


def _estimate_matrix(e: PoseEstimate) -> np.ndarray:
    return pose_matrix(e.translation, e.rotation)


def _in_world(e: PoseEstimate, camera_pose: np.ndarray) -> PoseEstimate:
    """The estimate moved from the camera frame to the world."""
    r, t = camera_pose[:3, :3], camera_pose[:3, 3]
    return replace(
        e,
        rotation=r @ e.rotation,
        translation=r @ e.translation + t,
        keypoints=e.keypoints @ r.T + t,
    )


class VisionNode(LeanNode):
    """The vision services (see the module docstring). ``close()`` before ``destroy_node()``."""

    def __init__(
        self, config: VisionConfig, mission: Mission | None = None, name: str = "vision", **node_kwargs: Any
    ) -> None:
        super().__init__(name, **node_kwargs)
        self.config = config
        raw = config.raw
        self.mission = mission or load_mission(config.mission_path)
        self.inspector = PartInspector(config, self.mission)
        self.parts, self.tol = self.inspector.parts, self.inspector.tol
        self.rig = CameraRig(config)
        self.ee_filter = EeSelfFilter.from_config(raw["ee_self_filter"])
        self._set_up_torch(raw["torch_threads"])
        self.tags = TagLocator(TagConfig.load())
        self.tag_ids = dispenser_tag_ids(list(self.mission.dispensers))
        self.tool = pose_of(raw["tool"])

        sensors = QuickCallbackGroup()  # stores only: called on the executor's own thread
        self.labels = SegmentationLabels(self, raw["topics"]["segmentation_labels"], sensors)
        seg = raw["segmentation"]
        if seg["source"] == "mask_rcnn":
            self.segmenter: Any = MaskRcnnSegmenter.from_config(self.config)
        else:
            self.segmenter = TwinLabels(lambda: self.labels.wait(0.0))
        self.grabber = FrameGrabber(self, raw["topics"]["image"])
        self._subscribe_joint_states(sensors)
        self.vision_services = [
            self.create_service(srv, name, cb, callback_group=MutuallyExclusiveCallbackGroup())
            for srv, name, cb in (
                (InspectPart, ros_names.VISION_INSPECT_PART, self._inspect_part),
                (InspectBay, ros_names.VISION_INSPECT_BAY, self._inspect_bay),
                (CheckAlignment, ros_names.VISION_CHECK_ALIGNMENT, self._check_alignment),
                (LocateTag, ros_names.VISION_LOCATE_TAG, self._locate_tag),
            )
        ]
        self.get_logger().info(
            f"vision ready: mission {self.mission.name}, segmentation {seg['source']}, "
            f"cameras {', '.join(config.cameras)}"
        )

    # ----- set-up -----
    @staticmethod
    def _set_up_torch(threads: int) -> None:
        """Fix torch's thread count (config ``torch_threads``) and import its compiler stack, which
        the first optimiser made pulls in (seconds of CPU), at start-up rather than inside the first
        request's time."""
        import torch

        torch.set_num_threads(threads)
        torch.optim.Adam([torch.zeros(1, requires_grad=True)])

    def _subscribe_joint_states(self, group: Any) -> None:
        def on_joints(msg: JointState) -> None:
            self.rig.joints.update(list(msg.name), list(msg.position), self._msg_time(msg))

        def on_ee(msg: EndEffectorState) -> None:
            self.rig.joints.update(list(msg.joint_names), list(msg.position), self._msg_time(msg))

        components = {ros_names.CAMERA_MOUNTS} if self.rig.lifter else set()
        arms = set(self.rig.arms)
        components |= {ros_names.ur(a) for a in arms}
        for c in sorted(components):
            self.create_subscription(
                JointState, ros_names.joint_states_topic(c), on_joints, 10, callback_group=group
            )
        for a in sorted(arms):
            self.create_subscription(
                EndEffectorState, ros_names.state_topic(ros_names.ee(a)), on_ee, 10, callback_group=group
            )

    def _msg_time(self, msg: Any) -> float:
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        return t if t > 0 else self._now()

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # ----- shared steps -----
    def _camera(self, name: str) -> str:
        camera = self.config.resolve_camera(name)
        if camera is None:
            known = ", ".join([*self.config.cameras, *self.config.raw["camera_aliases"]])
            raise NoFrame(f"unknown camera {name!r} (known: {known})")
        return camera

    def _grab(self, camera: str, streams: Sequence[str], deadline: float) -> CameraFrame:
        timeout = min(self.config.raw["timeouts"]["frame_s"], deadline - time.monotonic())
        if timeout <= 0:
            raise NoFrame(f"no time left for a frame from {camera}")
        return self.grabber.grab(camera, streams, self._now(), timeout)

    def _deadline(self) -> float:
        return time.monotonic() + self.config.raw["timeouts"]["request_s"]

    def _segment(self, frame: CameraFrame, doubtful: bool = False) -> list[Detection]:
        """The frame's detections scoring ``min_score`` or more; with ``doubtful`` down to the
        second look's score too (InspectPart's strut decides which it looks at again)."""
        try:
            detections = self.segmenter.detect(frame)
        except ValueError as exc:
            raise NoFrame(f"segmentation failed: {exc}") from exc
        if doubtful:
            return detections
        return [d for d in detections if d.score >= self.inspector.min_score]

    def _frame_streams(self) -> tuple[str, ...]:
        return ("depth", *self.segmenter.streams)

    def _observe(
        self, pipeline: str, detections: list[Detection], frame: CameraFrame, prior: Any = None
    ) -> list[inspection.Observation]:
        return self.inspector.observe(
            pipeline, detections, frame.get("depth"), frame.intrinsics, frame.get("rgb"), prior,
            self.config.depth_noise_of(frame.camera),
        )

    def _near(
        self, detections: list[Detection], frame: CameraFrame, camera_pose: np.ndarray,
        places: np.ndarray, piece: str,
    ) -> list[Detection]:
        """Only the ``piece`` detections that a check gated by ``held_piece_gate`` around
        ``places`` (world) could count; the others would cost a pose each for nothing."""
        radius = self.config.raw["held_piece_gate"] + self.inspector.estimators[piece].model.diameter / 2
        return detections_near(detections, frame.get("depth"), frame.intrinsics, camera_pose, places,
                               radius)

    def _report_msg(
        self, report: inspection.InspectionReport, stamp: float, frame_id: str, object_ids: dict[int, str]
    ) -> InspectionReport:
        msg = InspectionReport()
        set_stamp(msg.header.stamp, stamp)
        msg.header.frame_id = frame_id
        msg.target_id, msg.target_kind = report.target_id, report.target_kind
        msg.passed = bool(report.passed)
        msg.reasons = list(report.reasons)
        msg.poses = [
            self._certified_pose(e, stamp, frame_id, object_ids.get(id(e), "")) for e in report.poses
        ]
        return msg

    @staticmethod
    def _certified_pose(e: PoseEstimate, stamp: float, frame_id: str, object_id: str = "") -> CertifiedPose:
        f = e.certified_pose_fields(object_id)
        p = CertifiedPose()
        set_stamp(p.header.stamp, stamp)
        p.header.frame_id = frame_id
        p.object_class, p.object_id = f["object_class"], f["object_id"]
        p.pose.position.x, p.pose.position.y, p.pose.position.z = f["position"]
        o = p.pose.orientation
        o.x, o.y, o.z, o.w = f["orientation"]
        p.certified = f["certified"]
        p.chamfer_p90, p.chamfer_threshold = f["chamfer_p90"], f["chamfer_threshold"]
        p.keypoint_groups_visible = f["keypoint_groups_visible"]
        p.keypoint_groups_required = f["keypoint_groups_required"]
        p.reason = f["reason"]
        return p

    def _failed(self, target: str, kind: str, reason: str) -> InspectionReport:
        msg = InspectionReport()
        set_stamp(msg.header.stamp, self._now())
        msg.target_id, msg.target_kind, msg.passed, msg.reasons = target, kind, False, [reason]
        return msg

    # ----- InspectPart -----
    def _inspect_part(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            response.report = self.inspect_part(request.member_id, request.part_kind, request.camera)
        except Exception as exc:  # a service must answer: an unexpected error is a failed report
            log.exception("inspect_part failed")
            response.report = self._failed(request.member_id, request.part_kind, f"vision error: {exc}")
        self._log_report(f"inspect_part {request.part_kind} via {request.camera}", response.report, started)
        return response

    def _log_report(self, what: str, report: InspectionReport, started: float) -> None:
        """One line per answered inspection (alignment checks and tag locations likewise, in their
        own handlers): what was asked, the verdict with its reasons, and the wall time it took."""
        verdict = "passed" if report.passed else "failed: " + "; ".join(report.reasons)
        self.get_logger().info(
            f"{what} {report.target_id}: {verdict} ({time.monotonic() - started:.1f} s wall)"
        )

    def inspect_part(self, member_id: str, kind: str, camera_name: str) -> InspectionReport:
        deadline = self._deadline()
        if kind == "rivet":
            return self._inspect_rivet(member_id, camera_name, deadline)
        if kind not in (*STRUT_KINDS, "cross_frame"):
            return self._failed(
                member_id, kind, f"unknown part kind {kind!r} (vertical, diagonal, cross_frame, rivet)"
            )
        try:
            camera = self._camera(camera_name)
            frame = self._grab(camera, self._frame_streams(), deadline)
            detections = self._segment(frame, doubtful=True)
        except NoFrame as exc:
            return self._failed(member_id, kind, str(exc))
        depth = self._without_own_ee(frame)
        detections = off_own_ee(detections, own_pixels(frame.get("depth"), depth), self.ee_filter.own_share)
        report, obs = self.inspector.inspect(
            member_id, kind, detections, depth, frame.intrinsics, frame.get("rgb"), self._closer(frame),
            self.config.depth_noise_of(frame.camera),
        )
        ids = {id(o.estimate): o.object_id for o in obs if o.estimate is not None}
        return self._report_msg(report, frame.stamp, frame.frame_id, ids)

    def _closer(self, frame: CameraFrame) -> LookCloser | None:
        """The strut's closer look at a region of ``frame`` (``segmentation.second_look_closer``):
        Mask R-CNN only; the twin's labels leave nothing unseen to look for."""
        closer = self.config.raw["segmentation"]["second_look_closer"]
        if closer is None or not hasattr(self.segmenter, "detect_in"):
            return None
        return lambda region: self.segmenter.detect_in(frame, region, closer["scale"])

    def _without_own_ee(self, frame: CameraFrame) -> np.ndarray | None:
        """The frame's depth with the arms' end effectors taken out (:mod:`tlt_vision.self_filter`):
        a presented part's fittings sit beside its EE's rivet guns. An arm whose joint states are
        missing or old stays in, with a warning (both, when the camera's own pose is unknown)."""
        depth = frame.get("depth")
        if depth is None or self.ee_filter.empty:
            return depth
        try:
            camera_pose = self.rig.camera_pose(frame.camera, frame.stamp)
        except FrameUnavailable as exc:
            self.get_logger().warning(f"end effectors left in {frame.camera}'s depth: {exc}")
            return depth
        placed = []
        for arm in self.rig.arms:
            try:
                ee = self.rig.end_effector(arm, frame.stamp)
            except FrameUnavailable as exc:
                self.get_logger().warning(f"{arm}'s end effector left in {frame.camera}'s depth: {exc}")
                continue
            placed += self.ee_filter.place(camera_pose, *ee)
        return drop_inside(depth, frame.intrinsics, placed, self.ee_filter.margin)[0]

    def _inspect_rivet(self, member_id: str, camera_name: str, deadline: float) -> InspectionReport:
        """Is a rivet in gun ``<ars>/<gun>``: a certified rivet pose at the gun's muzzle, seen by the
        EE camera beside that gun (the request's camera must be on that arm)."""
        ars, _, gun = member_id.partition("/")
        cams = [c for c in self.rig.ee.values() if c.arm == ars and c.gun_name == gun]
        if not cams:
            return self._failed(member_id, "rivet", f"no EE camera watches rivet gun {member_id!r}")
        cam = cams[0]
        try:
            asked = self._camera(camera_name)
            if asked not in self.rig.ee or self.rig.ee[asked].arm != ars:
                raise NoFrame(f"camera {camera_name!r} is not on {ars}'s end effector")
            frame = self._grab(cam.name, self._frame_streams(), deadline)
            detections = [d for d in self._segment(frame) if d.object_class == "rivet"]
        except NoFrame as exc:
            return self._failed(member_id, "rivet", str(exc))
        muzzle = cam.gun_in_camera()
        radius = self.config.raw["rivet_in_gun_radius"]
        # Only a rivet near the muzzle can pass: the others in view (a feeder's, one already set
        # in the structure) would cost a pose each for nothing.
        reach = radius + self.inspector.estimators["rivet"].model.diameter / 2
        seen = detections
        detections = detections_near(seen, frame.get("depth"), frame.intrinsics, np.eye(4), muzzle, reach)
        elsewhere = len(seen) - len(detections)
        obs = self._observe("rivet", detections, frame)
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
        return self._report_msg(report, frame.stamp, frame.frame_id, {})

    # ----- InspectBay -----
    def _tower_origin(self, bay: int) -> np.ndarray:
        """Where the mission's tower frame stands (world) while bay ``bay`` is built and tested:
        the lifter holds the bays above at the build level, bay ``bay``'s frame on the floor."""
        site = self.config.raw["site"]
        return np.asarray(site["base_origin"]) + np.array(
            [0.0, 0.0, site["build_level"] + bay * self.mission.bay_height]
        )

    def _inspect_bay(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            response.report = self.inspect_bay(int(request.bay))
        except Exception as exc:
            log.exception("inspect_bay failed")
            response.report = self._failed(f"bay{request.bay}", "bay", f"vision error: {exc}")
        self._log_report("inspect_bay", response.report, started)
        return response

    def inspect_bay(self, bay: int) -> InspectionReport:
        deadline = self._deadline()
        target = f"bay{bay}"
        try:
            origin, joints = self._tower_origin(bay), inspection.bay_joints(self.mission, bay)
            expected = {k: origin + np.asarray(p) for k, p in joints.items()}
        except KeyError as exc:
            return self._failed(target, "bay", str(exc.args[0]))
        world = self.config.raw["world_frame"]
        found: list[tuple[inspection.Observation, str]] = []
        problems: list[str] = []
        stamp = self._now()
        for camera in self.config.raw["bay_cameras"]:
            try:
                frame = self._grab(camera, self._frame_streams(), deadline)
                pose = self.rig.camera_pose(camera, frame.stamp)
                detections = [d for d in self._segment(frame) if d.object_class == "corner_joint"]
            except (NoFrame, FrameUnavailable) as exc:
                problems.append(f"{camera}: {exc}")
                continue
            stamp = frame.stamp
            places = np.array(list(expected.values()))
            detections = self._near(detections, frame, pose, places, "corner_joint")
            for o in self._observe("bay", detections, frame, inspection.corner_joint_prior(places, pose)):
                est = _in_world(o.estimate, pose) if o.estimate is not None else None
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
                    and np.linalg.norm(m.estimate.translation - e.translation) < BAY_DUPLICATE_M
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
        return self._report_msg(report, stamp, world, ids)

    # ----- CheckAlignment -----
    def _check_alignment(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            self.check_alignment(request, response)
        except Exception as exc:
            log.exception("check_alignment failed")
            response.aligned, response.reason = False, f"vision error: {exc}"
        verdict = (
            f"aligned ({response.position_error * 1000:.1f} mm, {math.degrees(response.angle_error):.2f} deg)"
            if response.aligned
            else f"not aligned: {response.reason}"
        )
        self.get_logger().info(
            f"check_alignment {request.member_id} via {request.camera}: {verdict}"
            f" ({time.monotonic() - started:.1f} s wall)"
        )
        return response

    def check_alignment(self, request: Any, response: Any) -> Any:
        deadline = self._deadline()
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
        origin = self._tower_origin(member.bay)
        joints = [origin + np.asarray(p, dtype=float) for _, p in member.joints]
        try:
            camera = self._camera(request.camera)
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
        stamp = self._now()
        tool: np.ndarray | None = None
        # Every camera's frame and pose first, then the poses (seconds each on a busy CPU): the
        # frames are of one moment, and the request's time is not spent before the last is taken.
        frames: list[tuple[CameraFrame, np.ndarray, np.ndarray]] = []  # frame, camera pose, as held
        counts: list[str] = []  # what each camera saw, for a check that fails
        uncertified: list[str] = []
        for cam in sorted(c.name for c in self.rig.ee.values() if c.arm == arm):
            try:
                frame = self._grab(cam, self._frame_streams(), deadline)
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
                detections = [d for d in self._segment(frame) if d.object_class == piece]
            except NoFrame as exc:
                problems.append(f"{frame.camera}: {exc}")
                continue
            near = self._near(detections, frame, cam_pose, places, piece)
            certified = 0
            prior = inspection.corner_joint_prior(places, cam_pose) if piece == "corner_joint" else None
            for o in self._observe(pipeline, near, frame, prior):
                e = o.estimate
                if e is None or not e.certified:
                    uncertified.append(f"{frame.camera}: {o.reason or e.certificate.reason}")
                    continue
                certified += 1
                e = _in_world(e, held_pose)
                if all(np.linalg.norm(m.translation - e.translation) >= BAY_DUPLICATE_M for m in seen):
                    seen.append(e)
            counts.append(f"{frame.camera}: {len(detections)} segmented, {len(near)} near a place,"
                          f" {certified} certified")
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
            seen_how = [f"{piece}s: {', '.join(counts)}",
                        f"certified ones {', '.join(f'{d:.0f}' for d in off) or '-'} mm from a place",
                        *uncertified]
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

    # ----- LocateTag -----
    def tag_mount(self, dispenser: str) -> np.ndarray:
        """The tag's frame in its dispenser's frame, where the twin mounts it (node.yaml ``tag_mount``)."""
        return tag_mount(self.config.raw["tag_mount"], self.mission, dispenser, self.tags.config.tag_side)

    def _locate_tag(self, request: Any, response: Any) -> Any:
        started = time.monotonic()
        try:
            self.locate_tag(request, response)
        except Exception as exc:
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
        self.get_logger().info(
            f"locate_tag {request.dispenser} via {request.camera}: {verdict}"
            f" ({time.monotonic() - started:.1f} s wall)"
        )
        return response

    def locate_tag(self, request: Any, response: Any) -> Any:
        deadline = self._deadline()
        response.found = False
        if request.dispenser not in self.tag_ids:
            response.reason = f"unknown dispenser {request.dispenser!r}"
            return response
        tag_id = self.tag_ids[request.dispenser]
        response.tag_id = tag_id
        try:
            camera = self._camera(request.camera)
            frame = self._grab(camera, ("rgb",), deadline)
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


def build_node(
    config_path: str | Path = DEFAULT_CONFIG, mission: str | Path | None = None, **kw: Any
) -> VisionNode:
    """Load the configuration and build the node; ConfigError or WeightsError when refused."""
    return VisionNode(load_config(config_path, mission), **kw)


def main(argv: list[str] | None = None) -> int:
    """``tlt-vision [--config node.yaml] [--mission M.yaml] [--ros-args ...]``; 2 when refused."""
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args: list[str] = []
    if "--ros-args" in argv:
        at = argv.index("--ros-args")
        argv, ros_args = argv[:at], argv[at:]
    parser = argparse.ArgumentParser(prog="tlt-vision", description="The TLT vision node (paper §V.E).")
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="vision node configuration")
    parser.add_argument("--mission", type=Path, help="mission file (overrides the configuration's)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        config = load_config(args.config, args.mission)
        mission = load_mission(config.mission_path)
    except ConfigError as exc:
        print(f"tlt-vision: refused: {exc}", file=sys.stderr)
        return 2
    share_the_interpreter_quickly()  # poses are computed beside the executor's busy threads
    # rclpy's own handler would shut the context down under a pose being computed on an executor
    # thread: a signal asks the spin loop to end instead (tlt_common/stop_signals.py).
    stop = stop_on_signals()
    rclpy.init(args=["tlt-vision", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        try:
            node = VisionNode(config, mission)
        except (ConfigError, WeightsError, KeyError) as exc:
            print(f"tlt-vision: refused: {exc}", file=sys.stderr)
            return 2
        executor = DirectMultiThreadedExecutor(num_threads=8)
        executor.add_node(node)
        try:
            spin(executor, stop=lambda: bool(stop))
        except ExternalShutdownException:  # a context shut down by someone else
            pass
        finally:
            for exc in stop_executor(executor, 2.0):  # before the node's handles go
                node.get_logger().warning(f"a callback ended with {exc!r} at shutdown")
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
