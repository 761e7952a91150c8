"""The CRS's handling of the joints the ARSs verified, against stand-in ARS action servers: each
joint's record in the tower model and its event to the ground, the fault with the evidence that
waits for the operator when one is not good, and the operator's confirm and retry; a CRS that
restarts with a retry pending sends it."""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from tlt_common.mission.tower_model import RIVETED, TowerModel
from tlt_crs.behaviours.faults import failure_reason
from tlt_crs.tree import add_diagonal, add_vertical, member_joints

MEMBER = "bay1/vertical/x0_y1"  # ARS X adds it, ARS Y affixes it


def _strut(ctx, member, add=add_vertical):
    """The strut's figure, then its joints, as Build Bay has them."""
    return py_trees.composites.Sequence(
        "Strut", memory=True, children=[add(ctx, member), member_joints(ctx, member)]
    )


def _joint(member, step):
    return next(r.joint for r in member.rivets if r.step == step)


def _check(joint, state, verdict, *, shots=1, verdicts=None):
    return {
        "joint": joint,
        "state": state,
        "verdict": verdict,
        "reason": f"the stand-in saw {verdict}",
        "shots": shots,
        "looks": len(verdicts or [verdict]),
        "verdicts": verdicts or [verdict],
        "height": 0.0042 if verdict == "unseated" else 0.0,
        "pixels": 120 if verdict != "no_head" else 0,
        "camera": "ars_y/d405",
    }


def _setup(rig, crs, tmp_path, affix_results):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = ctx.mission.member(MEMBER)
    add, affix = _joint(member, "add"), _joint(member, "affix")
    rig.ars["ars_x"].joints[("add_member", MEMBER)] = [[_check(add, "verified", "good")]]
    rig.ars["ars_y"].joints[("affix_member", MEMBER)] = [[c] for c in affix_results(affix)]
    events = []
    ctx.event_listeners.append(lambda severity, code, text: events.append((severity, code, text)))
    return ctx, member, affix, events


def test_verified_joints_pass_each_with_its_event_and_a_reshot_takes_its_rivet(rig, crs, tmp_path):
    ctx, member, affix, events = _setup(
        rig, crs, tmp_path, lambda j: [_check(j, "verified", "good", shots=2, verdicts=["no_head", "good"])]
    )
    assert crs.tick_until(_strut(ctx, member)) == Status.SUCCESS
    assert ctx.model.states[MEMBER] == RIVETED
    records = ctx.model.joints_of(MEMBER)
    assert {j: r["state"] for j, r in records.items()} == {
        _joint(member, "add"): "verified",
        affix: "verified",
    }
    assert records[affix]["verdicts"] == ["no_head", "good"] and records[affix]["shots"] == 2
    codes = [code for _, code, _ in events]
    assert codes.count("JOINT_VERIFIED") == 2 and codes.count("JOINT_RESHOT") == 1
    # The vertical's two rivets and the reshot's: ARS Y took two from its dispenser.
    assert ctx.model.remaining["rivet_dispenser_x"] == 15 and ctx.model.remaining["rivet_dispenser_y"] == 14


def test_a_failed_joint_faults_with_its_evidence_and_the_operator_confirms_it(rig, crs, tmp_path):
    ctx, member, affix, events = _setup(
        rig, crs, tmp_path, lambda j: [_check(j, "failed", "unseated", shots=2, verdicts=["unseated"] * 2)]
    )
    subtree = _strut(ctx, member)
    assert crs.tick_until(subtree) == Status.FAILURE
    reason = failure_reason(subtree)
    assert f"joint {affix} failed: unseated" in reason and "+4.2 mm out" in reason
    assert "joint_decision" in reason and "clear_fault" in reason
    assert ("JOINT_FAILED" in [code for _, code, _ in events]) and events[-1][0] == 3
    # Persisted: a restarted CRS knows the joint wants the operator.
    assert TowerModel.load(ctx.mission, ctx.model.path).open_joints(MEMBER)[affix]["state"] == "failed"
    # The fault stands while nobody decides.
    assert crs.tick_until(subtree) == Status.FAILURE
    ctx.board.set("joint_decision", "confirm")
    assert crs.tick_until(subtree) == Status.SUCCESS
    assert ctx.model.joints_of(MEMBER)[affix]["state"] == "confirmed"
    assert ctx.board.get("joint_decision") == ""
    assert "JOINT_CONFIRMED" in [code for _, code, _ in events]
    assert len(rig.recorder.members("affix_member")) == 1  # nothing shot or placed again


def test_an_unverified_joint_wants_the_operator_too(rig, crs, tmp_path):
    ctx, member, affix, events = _setup(
        rig, crs, tmp_path, lambda j: [_check(j, "unverified", "cannot_judge", verdicts=["cannot_judge"] * 2)]
    )
    subtree = _strut(ctx, member)
    assert crs.tick_until(subtree) == Status.FAILURE
    assert f"joint {affix} unverified: cannot_judge" in failure_reason(subtree)
    assert "JOINT_UNVERIFIED" in [code for _, code, _ in events]


def test_the_operator_s_retry_shoots_the_joint_again_through_its_ars(rig, crs, tmp_path):
    ctx, member, affix, events = _setup(
        rig,
        crs,
        tmp_path,
        lambda j: [
            _check(j, "failed", "wrong_hole"),
            _check(j, "failed", "no_head"),  # the retry's first shot: still bad
            _check(j, "verified", "good"),
        ],
    )
    subtree = _strut(ctx, member)
    assert crs.tick_until(subtree) == Status.FAILURE
    ctx.board.set("joint_decision", "retry")
    assert crs.tick_until(subtree) == Status.FAILURE  # shot again, still bad: the fault again
    assert f"joint {affix} failed: no_head" in failure_reason(subtree)
    retry = rig.recorder.requests[-1]
    assert (retry.ars, retry.request, retry.member_id, retry.joint) == (
        "ars_y",
        "affix_member",
        MEMBER,
        affix,
    )
    assert ctx.model.remaining["rivet_dispenser_y"] == 14  # the retry's rivet
    ctx.board.set("joint_decision", "retry")
    assert crs.tick_until(subtree) == Status.SUCCESS
    assert ctx.model.joints_of(MEMBER)[affix]["state"] == "verified"
    assert [r.joint for r in rig.recorder.requests if r.request == "affix_member"] == ["", affix, affix]
    assert "JOINT_RETRY" in [code for _, code, _ in events]


def test_a_restarted_crs_sends_the_retry_the_operator_ordered(rig, crs, tmp_path):
    ctx, member, affix, _ = _setup(
        rig, crs, tmp_path, lambda j: [_check(j, "failed", "unseated"), _check(j, "verified", "good")]
    )
    assert crs.tick_until(_strut(ctx, member)) == Status.FAILURE
    ctx.model.decide_joint(MEMBER, affix, "retry")  # ordered, then the CRS died
    again = crs.make_context(rig, crs.fast_config(tmp_path))
    assert again.model.joints_of(MEMBER)[affix]["state"] == "retry"
    assert crs.tick_until(_strut(again, again.mission.member(MEMBER))) == Status.SUCCESS
    assert [r.joint for r in rig.recorder.requests if r.request == "affix_member"] == ["", affix]
    assert rig.recorder.members("add_member") == [MEMBER]  # never placed twice


def test_a_result_without_joints_leaves_the_member_accepted(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = ctx.mission.member("bay1/diagonal/face_x0")
    assert crs.tick_until(_strut(ctx, member, add_diagonal)) == Status.SUCCESS
    assert ctx.model.joints_of(member.id) == {}
