"""Vision requests of the ARS (paper §V.C.3, §V.E): a dispenser's AprilTag for the fine approach,
the alignment of a held or placed part from the EE camera, and the check that a rivet is loaded.

* :class:`LocateDispenser` calls ``LocateTag`` (``ros_names.VISION_LOCATE_TAG``) and stores the
  dispenser's world pose (the tag marks the dispenser's origin) in ``RequestData.located``; the
  fine approach then takes its grasp pose from there instead of from the mission.
* :class:`MeasureAlignment` calls ``CheckAlignment`` (``ros_names.VISION_CHECK_ALIGNMENT``) with
  the EE camera and stores the response in ``RequestData.alignment``; :class:`PartAligned` reads
  it; :func:`corrected_target` turns a measured part pose into the tool pose that puts the part
  where it belongs.
* :func:`verify_rivet_loaded` asks ``InspectPart`` (``ros_names.VISION_INSPECT_PART``) about the
  rivet in the gun (part kind ``rivet``, member id ``<ars>/<gun>``, the EE camera).

Poses from vision must be in ``cameras.world_frame``; any other frame fails with that reason.

Each question survives a restart of the vision process (:func:`vision_call_options`): one that got
no response because vision was killed with it is asked again once the new vision says ready on
``ros_names.VISION_STATUS``, up to ``vision_retries`` times, each waiting up to
``timeouts.vision_back_s`` for vision to come back.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
from tlt_interfaces.srv import CheckAlignment, InspectPart, LocateTag

from tlt_ars.context import ArsContext
from tlt_ars.planning.targets import Target, dispenser_targets, part_in_tool
from tlt_common import ros_names
from tlt_common.bt.nodes import Condition
from tlt_common.bt.ros import ServiceCall
from tlt_common.geometry.transforms import invert, pose_matrix, quaternion_to_rotation, rpy_from_matrix


def vision_call_options(ctx: ArsContext) -> dict[str, Any]:
    """The limits of a question to vision, and how it is asked again after a vision restart."""
    timeouts = ctx.config.timeouts
    return {
        "service_timeout": timeouts["server_s"],
        "timeout": timeouts["service_s"],
        "clock": ctx.clock,
        "retries": ctx.config.raw["vision_retries"],
        "server_state": ctx.vision_status,
        "back_within": timeouts["vision_back_s"],
    }


def pose_to_matrix(pose: Any) -> np.ndarray:
    """geometry_msgs/Pose -> 4x4; ``ValueError`` for a zero quaternion."""
    o = pose.orientation
    rot = quaternion_to_rotation((o.x, o.y, o.z, o.w))
    return pose_matrix((pose.position.x, pose.position.y, pose.position.z), rot)


class LocateDispenser(ServiceCall):
    """Find ``dispenser``'s AprilTag with the EE camera.

    Writes: ``RequestData.located[dispenser]`` (world pose). RUNNING while vision answers.
    SUCCESS with a tag found in the world frame. FAILURE when vision is missing or slow, the tag
    is not found (vision's reason), or the pose is in another frame.
    """

    def __init__(self, name: str, ctx: ArsContext, dispenser: str) -> None:
        self.ctx = ctx
        self.dispenser = dispenser
        super().__init__(
            name,
            ctx.node,
            LocateTag,
            ros_names.VISION_LOCATE_TAG,
            lambda: LocateTag.Request(dispenser=dispenser, camera=ctx.config.cameras["end_effector"]),
            response_ok=self._ok,
            **vision_call_options(ctx),
        )

    def _ok(self, response: Any) -> tuple[bool, str]:
        if not response.found:
            return False, f"tag of '{self.dispenser}' not found: {response.reason or 'no reason given'}"
        frame = response.pose.header.frame_id
        if frame != self.ctx.config.cameras["world_frame"]:
            return (
                False,
                f"tag pose is in frame '{frame}', expected '{self.ctx.config.cameras['world_frame']}'",
            )
        try:
            self.ctx.data.located[self.dispenser] = pose_to_matrix(response.pose.pose)
        except ValueError as exc:
            return False, str(exc)
        return True, ""


def located_dispenser_targets(ctx: ArsContext, dispenser: str) -> list[Target]:
    """Grasp candidates for the top part of ``dispenser``, placed where its tag was seen (or where
    the mission says, before the tag is located)."""
    disp = ctx.mission.dispensers[dispenser]
    seen = ctx.data.located.get(dispenser)
    mission: Any = ctx.mission
    if seen is not None:
        origin = np.asarray(ctx.scene.raw["site"]["base_origin"], dtype=float)
        # A dispenser stands on the floor: its roll and pitch are the mission's, and only its place
        # and heading are taken from the tag, whose tilt is the least certain part of its pose (a
        # degree of it tilts the tool's whole bar, which passes centimetres from the pedestal).
        roll, pitch, _ = disp.rpy
        yaw = rpy_from_matrix(seen[:3, :3])[2]
        disp = replace(disp, position=tuple(seen[:3, 3] - origin), rpy=(roll, pitch, float(yaw)))
        mission = SimpleNamespace(
            dispensers={dispenser: disp},
            bay_width=ctx.mission.bay_width,
            strut_lengths=ctx.mission.strut_lengths,
        )
    return dispenser_targets(ctx.scene, mission, dispenser, ctx.ars, remaining=ctx.state.remaining[dispenser])


class MeasureAlignment(ServiceCall):
    """Ask vision for the alignment of the request's member from the EE camera.

    Writes: ``RequestData.alignment`` (the response). SUCCESS when vision answered (aligned or
    not: :class:`PartAligned` judges); FAILURE when vision is missing or slow.
    """

    def __init__(self, name: str, ctx: ArsContext) -> None:
        self.ctx = ctx
        super().__init__(
            name,
            ctx.node,
            CheckAlignment,
            ros_names.VISION_CHECK_ALIGNMENT,
            self._request,
            response_ok=self._ok,
            **vision_call_options(ctx),
        )

    def _request(self) -> Any:
        member = self.ctx.data.member
        if member is None:
            raise RuntimeError("no member to align")
        return CheckAlignment.Request(member_id=member.id, camera=self.ctx.config.cameras["end_effector"])

    def _ok(self, response: Any) -> tuple[bool, str]:
        self.ctx.data.alignment = response
        return True, ""


class PartAligned(Condition):
    """True when the latest alignment measurement says aligned. Reads ``RequestData.alignment``."""

    def __init__(self, name: str, ctx: ArsContext) -> None:
        super().__init__(name)
        self.ctx = ctx

    def evaluate(self) -> bool:
        a = self.ctx.data.alignment
        if a is None:
            self.feedback_message = "not measured"
            return False
        self.feedback_message = (
            f"{'aligned' if a.aligned else 'misaligned'}: {a.position_error * 1000:.1f} mm,"
            f" {np.degrees(a.angle_error):.2f} deg" + (f" ({a.reason})" if a.reason else "")
        )
        return bool(a.aligned)


class AlignmentSeen(Condition):
    """True when the latest alignment measurement saw the part: its pose is certified, however far
    off it is. False when vision did not see enough of it (a view missed an end piece), which is
    worth a second look before the measurement is judged. Reads ``RequestData.alignment``."""

    def __init__(self, name: str, ctx: ArsContext) -> None:
        super().__init__(name)
        self.ctx = ctx

    def evaluate(self) -> bool:
        a = self.ctx.data.alignment
        seen = a is not None and bool(a.pose.certified)
        self.feedback_message = "seen" if seen else "not seen" if a is None else f"not seen: {a.reason}"
        return seen


def corrected_target(ctx: ArsContext, key: str) -> Target:
    """The tool pose that moves the held part from where vision saw it to the chosen placement
    target ``RequestData.targets[key]`` (the part frame is the tool frame at the grasp)."""
    a = ctx.data.alignment
    target = ctx.data.targets.get(key)
    if a is None or target is None:
        raise RuntimeError("no alignment measurement or placement target")
    if not a.pose.certified:
        raise RuntimeError(f"vision pose of the part is not certified: {a.pose.reason}")
    if a.pose.header.frame_id != ctx.config.cameras["world_frame"]:
        raise RuntimeError(f"part pose is in frame '{a.pose.header.frame_id}'")
    q = ctx.arm_q()
    if q is None:
        raise RuntimeError("no fresh joint state")
    tool = ctx.scene.kinematics(ctx.ars).forward(q)
    measured = pose_to_matrix(a.pose.pose)
    # Vision reports the part's frame (its middle); a diagonal's is off the tool (held_offset).
    part_target = target.pose @ part_in_tool(ctx.mission, ctx.data.member.kind)
    pose = part_target @ invert(measured) @ tool
    return Target(f"{target.label} corrected", pose, target.pre_pose)


def verify_rivet_loaded(ctx: ArsContext, name: str = "Verify Rivet Loaded") -> ServiceCall:
    """The EE camera confirms a rivet sits in the gun (InspectPart, part kind ``rivet``)."""
    gun = ctx.config.ee["rivet_gun"]

    def ok(response: Any) -> tuple[bool, str]:
        report = response.report
        return bool(report.passed), "; ".join(report.reasons) or "rivet not seen in the gun"

    return ServiceCall(
        name,
        ctx.node,
        InspectPart,
        ros_names.VISION_INSPECT_PART,
        lambda: InspectPart.Request(
            member_id=f"{ctx.ars}/{gun}", part_kind="rivet", camera=ctx.config.cameras["end_effector"]
        ),
        response_ok=ok,
        **vision_call_options(ctx),
    )


__all__ = [
    "AlignmentSeen",
    "LocateDispenser",
    "MeasureAlignment",
    "PartAligned",
    "corrected_target",
    "located_dispenser_targets",
    "pose_to_matrix",
    "verify_rivet_loaded",
    "vision_call_options",
]
