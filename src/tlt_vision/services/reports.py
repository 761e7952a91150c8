"""The messages the vision services answer with, and the log line of each answer."""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import Pose
from rclpy.impl.rcutils_logger import RcutilsLogger
from tlt_interfaces.msg import CertifiedPose, InspectionReport

from tlt_common.geometry.transforms import rotation_to_quaternion
from tlt_common.ros.stamps import set_stamp
from tlt_vision import inspection
from tlt_vision.pose.estimator import PoseEstimate


def pose_msg(t: np.ndarray) -> Pose:
    """The 4x4 transform ``t`` as a Pose."""
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in t[:3, 3])
    x, y, z, w = rotation_to_quaternion(t[:3, :3])
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = x, y, z, w
    return p


def certified_pose(e: PoseEstimate, stamp: float, frame_id: str, object_id: str = "") -> CertifiedPose:
    """The estimate with its certificate, in ``frame_id`` at ``stamp`` (ROS time, s)."""
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


def report_msg(
    report: inspection.InspectionReport, stamp: float, frame_id: str, object_ids: dict[int, str]
) -> InspectionReport:
    """The decision as the message, its poses in ``frame_id``; ``object_ids`` maps ``id()`` of an
    estimate to the twin's or the mission's name of what it poses."""
    msg = InspectionReport()
    set_stamp(msg.header.stamp, stamp)
    msg.header.frame_id = frame_id
    msg.target_id, msg.target_kind = report.target_id, report.target_kind
    msg.passed = bool(report.passed)
    msg.cannot_judge = bool(report.cannot_judge)
    msg.reasons = list(report.reasons)
    msg.poses = [certified_pose(e, stamp, frame_id, object_ids.get(id(e), "")) for e in report.poses]
    return msg


def failed_report(target: str, kind: str, reason: str, stamp: float) -> InspectionReport:
    """A failed report with its one reason and no pose."""
    msg = InspectionReport()
    set_stamp(msg.header.stamp, stamp)
    msg.target_id, msg.target_kind, msg.passed, msg.reasons = target, kind, False, [reason]
    return msg


def log_report(logger: RcutilsLogger, what: str, report: InspectionReport, started: float) -> None:
    """One line per answered inspection: what was asked, the verdict with its reasons, and the wall
    time it took since ``started`` (``time.monotonic()``)."""
    verdict = "passed" if report.passed else "failed: " + "; ".join(report.reasons)
    logger.info(f"{what} {report.target_id}: {verdict} ({time.monotonic() - started:.1f} s wall)")
