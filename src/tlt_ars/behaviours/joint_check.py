"""Verify Joint (paper §VI's "identification of joint faults and success joining", §VII's rivet V&V
left to an operator on the EDU): after a rivet shot, the EE camera looks at the joint and vision
judges it (``VerifyJoint``, ``ros_names.VISION_VERIFY_JOINT``).

* :class:`LookAtJoint` asks vision about the request's joint where the ARS's own model puts it:
  the mission's joint point where the tower stands (``tlt_ars.planning.world.tower_origin``), the
  member's axis towards its other joint, and the side the gun fired from (the tool's -z, from the
  arm's joint states). Every answer is a :class:`~tlt_ars.request_data.JointLook` in
  ``RequestData.looks``; a vision that is missing, slow or cannot be asked is a look that could not
  judge, never a pass and never a failure of the request (the member is set by then).
* :class:`JointJudged` (a look with a verdict since the last shot), :class:`JointSettled` (no new
  rivet wanted: judged good, not judged at all, or no reshot left) and :class:`CountShot` (a shot at
  the joint, kept in the state file) drive the subtree
  (:meth:`tlt_ars.subtrees.SubtreeBuilder.verify_joint`, ``reshoot_joint``).
* :func:`joint_state` says how the request leaves the joint: ``verified``, ``failed``,
  ``unverified``, or "" (never looked at); :func:`joint_checks` is the result's ``joints``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from py_trees.common import Status
from tlt_interfaces.msg import JointCheck
from tlt_interfaces.srv import VerifyJoint

from tlt_ars.context import ArsContext
from tlt_ars.planning.world import tower_origin
from tlt_ars.request_data import JointLook, RequestData
from tlt_common import ros_names
from tlt_common.bt.nodes import Action, Condition
from tlt_common.bt.ros import ServiceCall

GOOD, CANNOT_JUDGE = "good", "cannot_judge"
BAD_VERDICTS = ("no_head", "unseated", "wrong_hole")  # a new rivet can fix each (the old drilled out)
VERIFIED, FAILED, UNVERIFIED = "verified", "failed", "unverified"
_STEPS = {"add_member": "add", "affix_member": "affix"}  # the mission rivet step each request shoots


def joint_geometry(ctx: ArsContext, joint: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(joint point, member axis towards its other joint, side the gun fired from), world frame,
    for ``joint`` of the request's member with the arm where it stands. ``RuntimeError`` without a
    member, a joint of it, or a fresh joint state."""
    member = ctx.data.member
    if member is None:
        raise RuntimeError("no member in this request")
    points = dict(member.joints)
    if joint not in points or len(points) < 2:
        raise RuntimeError(f"member {member.id} has no joint {joint!r} between two ends")
    origin = tower_origin(ctx.scene, ctx.mission, member.bay)
    here = origin + np.asarray(points[joint], dtype=float)
    there = origin + np.asarray(next(p for k, p in member.joints if k != joint), dtype=float)
    q = ctx.arm_q()
    if q is None:
        raise RuntimeError("no fresh joint state to tell the side the gun fired from")
    tool = ctx.scene.kinematics(ctx.ars).forward(q)
    return here, (there - here) / np.linalg.norm(there - here), -tool[:3, 2]


def _point(msg: Any, v: np.ndarray) -> Any:
    msg.x, msg.y, msg.z = (float(c) for c in v)
    return msg


class LookAtJoint(ServiceCall):
    """Ask vision to judge ``joint`` of the request's member from the EE camera.

    Reads: ``RequestData.member``, ``shots``, the arm's joint states. Writes: a
    :class:`JointLook` appended to ``RequestData.looks`` (kept in the state file). RUNNING while
    vision answers; SUCCESS once it answered, or could not be asked or did not answer in time
    (then a ``cannot_judge`` look with that reason). Never FAILURE: a joint that cannot be looked at
    is reported unverified, and the member it belongs to stays set.
    """

    def __init__(self, name: str, ctx: ArsContext, joint: str) -> None:
        self.ctx = ctx
        self.joint = joint
        super().__init__(
            name,
            ctx.node,
            VerifyJoint,
            ros_names.VISION_VERIFY_JOINT,
            self._request,
            service_timeout=ctx.config.timeouts["server_s"],
            timeout=ctx.config.timeouts["service_s"],
            response_ok=self._ok,
            clock=ctx.clock,
        )

    def _request(self) -> Any:
        here, along, outward = joint_geometry(self.ctx, self.joint)
        request = VerifyJoint.Request(
            joint_id=f"{self.ctx.data.member.id}@{self.joint}", camera=self.ctx.config.cameras["end_effector"]
        )
        _point(request.joint, here)
        _point(request.along, along)
        _point(request.outward, outward)
        return request

    def _ok(self, response: Any) -> tuple[bool, str]:
        head = None
        if response.pixels:
            head = (float(response.head.x), float(response.head.y), float(response.head.z))
        self._note(
            JointLook(
                joint=self.joint,
                shot=self.ctx.data.shots,
                verdict=str(response.verdict),
                reason=str(response.reason),
                height=float(response.height),
                along=float(response.along_offset),
                pixels=int(response.pixels),
                head=head,
                camera=self.ctx.config.cameras["end_effector"],
            )
        )
        return True, ""

    def update(self) -> Status:
        status = super().update()
        if status != Status.FAILURE:
            return status
        why = self.feedback_message
        self._note(JointLook(self.joint, self.ctx.data.shots, CANNOT_JUDGE, f"no answer from vision: {why}"))
        return Status.SUCCESS

    def _note(self, look: JointLook) -> None:
        self.ctx.data.looks.append(look)
        self.feedback_message = f"{look.verdict}: {look.reason}"
        if (why := self.ctx.keep()) is not None:
            self.feedback_message += f" (not kept: {why})"


def last_look(data: RequestData) -> JointLook | None:
    """The latest look at the request's joint since its latest shot, or None."""
    if data.looks and data.looks[-1].shot == data.shots:
        return data.looks[-1]
    return None


class JointJudged(Condition):
    """True when the latest look since the last shot has a verdict (not ``cannot_judge``).
    Reads: ``RequestData.looks``, ``shots``."""

    def __init__(self, name: str, ctx: ArsContext) -> None:
        super().__init__(name)
        self.ctx = ctx

    def evaluate(self) -> bool:
        look = last_look(self.ctx.data)
        self.feedback_message = "not looked at" if look is None else f"{look.verdict}: {look.reason}"
        return look is not None and look.verdict != CANNOT_JUDGE


class JointSettled(Condition):
    """True when the joint wants no new rivet: its latest look since the last shot is good, or
    could not judge (unverified: a rivet that may be good is not shot over), or ``reshots`` new
    rivets were shot already. False for a bad verdict with a reshot left. Reads:
    ``RequestData.looks``, ``shots``."""

    def __init__(self, name: str, ctx: ArsContext, reshots: int) -> None:
        super().__init__(name)
        self.ctx = ctx
        self.reshots = reshots

    def evaluate(self) -> bool:
        data = self.ctx.data
        look = last_look(data)
        if look is None or look.verdict not in BAD_VERDICTS:
            self.feedback_message = "no look" if look is None else look.verdict
            return True
        left = self.reshots - max(0, data.shots - 1)
        self.feedback_message = f"{look.verdict}: {look.reason}; {left} reshot(s) left"
        return left <= 0


class CountShot(Action):
    """A rivet shot at the request's joint: ``RequestData.shots`` += 1, kept in the state file.
    SUCCESS; FAILURE when the state file cannot be written (the reason)."""

    def __init__(self, name: str, ctx: ArsContext) -> None:
        super().__init__(name)
        self.ctx = ctx

    def update(self) -> Status:
        self.ctx.data.shots += 1
        if (why := self.ctx.keep()) is not None:
            return self.fail(why)
        self.feedback_message = f"shot {self.ctx.data.shots}"
        return Status.SUCCESS


def joint_state(data: RequestData) -> str:
    """How the request leaves its joint: ``verified`` (the last look since the last shot saw a
    good head), ``failed`` (a bad one), ``unverified`` (it could not judge, or no look followed the
    last shot), or "" when the joint was neither shot at (counted) nor looked at."""
    if not data.looks:
        return UNVERIFIED if data.shots else ""
    look = last_look(data)
    if look is None or look.verdict == CANNOT_JUDGE:
        return UNVERIFIED
    return VERIFIED if look.verdict == GOOD else FAILED


def judged_look(data: RequestData) -> JointLook | None:
    """The last look with a verdict since the last shot (the evidence), else the last look."""
    judged = [look for look in data.looks if look.shot == data.shots and look.verdict != CANNOT_JUDGE]
    return judged[-1] if judged else (data.looks[-1] if data.looks else None)


def _shot_joint(data: RequestData) -> str:
    """The joint the request shoots: the one it names (a reshot), else its step's in the mission."""
    request, member = data.request, data.member
    if request is None or member is None:
        return ""
    if request.joint:
        return request.joint
    step = _STEPS.get(request.request)
    return next((r.joint for r in member.rivets if r.step == step), "")


def joint_checks(data: RequestData) -> list[Any]:
    """The result's ``joints``: one JointCheck for the request's joint when it was shot at or
    looked at (its state, the evidence of its last judged look, every look's verdict), else none."""
    state = joint_state(data)
    if not state or data.member is None:
        return []
    look = judged_look(data) or JointLook(_shot_joint(data), data.shots, "", "shot, never looked at")
    check = JointCheck(
        member_id=data.member.id,
        joint=look.joint,
        state=state,
        verdict=look.verdict,
        reason=look.reason,
        shots=data.shots,
        looks=len(data.looks),
        verdicts=[seen.verdict for seen in data.looks],
        height=look.height,
        along_offset=look.along,
        pixels=look.pixels,
        camera=look.camera,
    )
    if look.head is not None:
        _point(check.head, np.asarray(look.head))
    return [check]


__all__ = [
    "BAD_VERDICTS",
    "FAILED",
    "UNVERIFIED",
    "VERIFIED",
    "CountShot",
    "JointJudged",
    "JointSettled",
    "LookAtJoint",
    "joint_checks",
    "joint_geometry",
    "joint_state",
    "judged_look",
    "last_look",
]
