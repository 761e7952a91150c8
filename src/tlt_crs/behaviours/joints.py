"""Riveted joints as the ARSs verified them, and what the CRS does with one that is not good
(paper §VII: the rivet V&V the EDU left to an operator; the operator stays the fall-back).

An ARS that verifies its joints (``verify_joints`` in its file) reports each joint it shot in its
result's ``joints`` (``tlt_interfaces/JointCheck``): verified, failed (still bad after its
reshots) or unverified (vision could not judge it), with the evidence. :func:`record_joints` keeps
that in the tower model (persisted: a restarted CRS knows it) and tells the ground: an event per
joint, ``JOINT_VERIFIED``, ``JOINT_UNVERIFIED`` or ``JOINT_FAILED``, and ``JOINT_RESHOT`` when the
ARS needed more than one shot. The rivets of the reshots are taken from the joint's dispenser (a
misfired rivet shot again from the gun counts as a new one: the model never shows a rivet that is
not there).

After a member's requests, the tree checks its joints (:func:`tlt_crs.tree.member_joints`):
:class:`JointsAccepted` passes when each is verified or confirmed; otherwise
:class:`ApplyJointDecision` fails with the evidence, which raises the fault, and the CRS waits for
help. The operator then writes ``joint_decision`` (``confirm``: the joints are good as they stand;
``retry``: shoot them again) and clears the fault, or sends Stop. A retry is an Affix Member request
naming the joint (:func:`reshot_request`) to the ARS that rivets it, whose result is recorded like
any other; a joint still not good raises the fault again with the new evidence.
"""

from __future__ import annotations

from typing import Any

from py_trees.common import Status

from tlt_common.bt.nodes import Action, Condition
from tlt_common.mission.schema import Member
from tlt_common.mission.tower_model import TransitionRefused
from tlt_crs.behaviours.ars_requests import ArsRequest
from tlt_crs.context import CrsContext

DECISION_KEY = "joint_decision"
DECISIONS = {"confirm": "confirmed", "retry": "retry"}
_EVENTS = {
    "verified": (1, "JOINT_VERIFIED"),
    "unverified": (2, "JOINT_UNVERIFIED"),
    "failed": (3, "JOINT_FAILED"),
}


def evidence(joint: str, record: dict[str, Any]) -> str:
    """One line an operator can judge ``joint`` by: its state, the last verdict and its reason,
    the figures, the shots and every look's verdict."""
    figures = (
        f"head {1000 * record['height']:+.1f} mm out, {1000 * record['along']:+.1f} mm along,"
        f" {record['pixels']} px"
        if record["pixels"]
        else "no head measured"
    )
    return (
        f"joint {joint} {record['state']}: {record['verdict'] or 'no look'}: {record['reason']} ({figures};"
        f" {record['shots']} shot(s), looks {', '.join(record['verdicts']) or 'none'};"
        f" camera {record['camera'] or '?'})"
    )


def _record_of(check: Any) -> dict[str, Any]:
    head = check.head
    return {
        "state": str(check.state),
        "verdict": str(check.verdict),
        "reason": str(check.reason),
        "shots": int(check.shots),
        "looks": int(check.looks),
        "verdicts": [str(v) for v in check.verdicts],
        "height": float(check.height),
        "along": float(check.along_offset),
        "pixels": int(check.pixels),
        "head": [float(head.x), float(head.y), float(head.z)] if check.pixels else None,
        "camera": str(check.camera),
    }


def record_joints(ctx: CrsContext, member: Member, result: Any, *, rivets_taken: int = 1) -> None:
    """Keep the result's ``joints`` of ``member`` in the tower model, send an event per joint, and
    take the rivets shot beyond ``rivets_taken`` from each joint's dispenser."""
    for check in getattr(result, "joints", ()) or ():
        if check.member_id != member.id:
            ctx.event(2, "MODEL_DISAGREES", f"ARS reported joint {check.joint} of '{check.member_id}'"
                      f" in its result for '{member.id}'")  # fmt: skip
            continue
        record = _record_of(check)
        try:
            ctx.model.record_joint(member.id, check.joint, record)
        except TransitionRefused as exc:
            ctx.event(2, "MODEL_DISAGREES", f"tower model refused a joint's record: {exc.reason}")
            continue
        line = evidence(check.joint, record)
        if record["shots"] > 1:
            ctx.event(2, "JOINT_RESHOT", f"{member.id}: {line}")
        severity, code = _EVENTS.get(record["state"], (2, "JOINT_UNVERIFIED"))
        ctx.event(severity, code, f"{member.id}: {line}")
        rivet = next((r for r in member.rivets if r.joint == check.joint), None)
        extra = record["shots"] - rivets_taken
        if rivet is not None and extra > 0:
            try:
                ctx.model.take_part(rivet.dispenser, extra)
            except TransitionRefused as exc:
                ctx.event(2, "MODEL_DISAGREES", f"tower model refused a reshot's rivets: {exc.reason}")


class JointsAccepted(Condition):
    """True when every joint of ``member`` that was looked at is verified or confirmed by the
    operator (a joint never looked at has no record and passes).

    Reads: the tower model's joint records. SUCCESS / FAILURE accordingly (feedback: the
    evidence of the first joint that wants the operator)."""

    def __init__(self, ctx: CrsContext, member: Member) -> None:
        super().__init__(f"{member.id} Joints Accepted?")
        self.ctx = ctx
        self.member = member

    def evaluate(self) -> bool:
        open_joints = self.ctx.model.open_joints(self.member.id)
        if not open_joints:
            self.feedback_message = "every joint verified or confirmed"
            return True
        joint, record = next(iter(open_joints.items()))
        self.feedback_message = evidence(joint, record)
        return False


class ApplyJointDecision(Action):
    """Apply the operator's decision on ``member``'s joints that want one.

    Reads: blackboard ``joint_decision`` (``confirm``, ``retry`` or empty), the tower model's joint
    records. Writes: the records' states (``confirmed`` / ``retry``, persisted), ``joint_decision``
    = "" once applied, a ``JOINT_CONFIRMED`` or ``JOINT_RETRY`` event per joint. SUCCESS when a
    decision was applied, or a retry is pending already (ordered before a restart). FAILURE with
    the evidence and what the operator may do, which raises the fault: the tree waits for help.
    """

    def __init__(self, ctx: CrsContext, member: Member) -> None:
        super().__init__(f"Operator Decides {member.id}")
        self.ctx = ctx
        self.member = member

    def update(self) -> Status:
        model, board = self.ctx.model, self.ctx.board
        open_joints = model.open_joints(self.member.id)
        decision = str(board.get(DECISION_KEY, "") or "")
        if decision in DECISIONS:
            state = DECISIONS[decision]
            for joint, record in open_joints.items():
                if record["state"] != state:
                    model.decide_joint(self.member.id, joint, state)
                code = "JOINT_CONFIRMED" if state == "confirmed" else "JOINT_RETRY"
                self.ctx.event(2, code, f"{self.member.id}: operator {decision}s joint {joint}")
            board.set(DECISION_KEY, "")
            self.feedback_message = f"operator: {decision}"
            return Status.SUCCESS
        if any(r["state"] == "retry" for r in open_joints.values()):
            self.feedback_message = "a retry is pending"
            return Status.SUCCESS
        lines = "; ".join(evidence(j, r) for j, r in open_joints.items())
        return self.fail(
            f"{self.member.id}: {lines}. Set {DECISION_KEY} to confirm (good as it stands) or retry"
            " (shoot it again), then clear_fault; or Stop"
        )


class RetryPending(Condition):
    """True when a joint of ``member`` waits for the operator's retry. Reads: the tower model."""

    def __init__(self, ctx: CrsContext, member: Member) -> None:
        super().__init__(f"{member.id} Retry Pending?")
        self.ctx = ctx
        self.member = member

    def evaluate(self) -> bool:
        return retry_joint(self.ctx, self.member) is not None


def retry_joint(ctx: CrsContext, member: Member) -> str | None:
    """The first joint of ``member`` with a retry pending, or None."""
    return next((j for j, r in ctx.model.joints_of(member.id).items() if r["state"] == "retry"), None)


def record_reshot(ctx: CrsContext, member: Member, result: Any, ok: bool) -> None:
    """After an operator's retry (Affix Member naming the joint): the joint's new record; every
    shot took a new rivet. A failed request leaves the retry pending."""
    if ok:
        with ctx.model.lock:
            record_joints(ctx, member, result, rivets_taken=0)


def reshot_request(ctx: CrsContext, member: Member) -> ArsRequest:
    """Affix Member naming ``member``'s joint with a retry pending, to the ARS that rivets it."""
    from tlt_interfaces.action import AffixMember

    def joint() -> str:
        name = retry_joint(ctx, member)
        if name is None:
            raise RuntimeError(f"no joint of '{member.id}' waits for a retry")
        return name

    def ars() -> str:
        name = joint()
        return next(r.ars for r in member.rivets if r.joint == name)

    def goal(to: str) -> Any:
        return AffixMember.Goal(
            kind={"vertical": 1, "diagonal": 2}[member.kind],
            bay=member.bay,
            member_id=member.id,
            position=member.position,
            ars=to,
            joint=joint(),
        )

    return ArsRequest(ctx, AffixMember, "affix_member", member, ars, goal, record_reshot)


__all__ = [
    "DECISION_KEY",
    "ApplyJointDecision",
    "JointsAccepted",
    "RetryPending",
    "evidence",
    "record_joints",
    "record_reshot",
    "reshot_request",
    "retry_joint",
]
