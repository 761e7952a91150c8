"""Verify Joint, climbing the tree: the leaves (what each reads and writes, when each succeeds,
fails or runs), then Rivet Member's shot with its look, look again and reshot against a stand-in
vision serving VerifyJoint with scripted verdicts. The arm, the gun and the jaws are scripted
here (the ARS request tests run them on the emulated devices); the request geometry comes from
the shipped ARS and scene files and the one-bay mission."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest
import rclpy
from py_trees.common import Status
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from tlt_interfaces.srv import VerifyJoint
from tlt_sim.model.config import REPO_ROOT

import tlt_ars.subtrees as subtrees
from tlt_ars.behaviours.joint_check import (
    CountShot,
    JointJudged,
    JointSettled,
    LookAtJoint,
    joint_checks,
    joint_geometry,
    joint_state,
)
from tlt_ars.config import ars_config_from_dict, default_config_path
from tlt_ars.mission_state import Request
from tlt_ars.planning.world import load_scene_config, tower_origin
from tlt_ars.request_data import JointLook, RequestData, RequestFile
from tlt_ars.subtrees import SubtreeBuilder
from tlt_common import ros_names
from tlt_common.bt.nodes import Action
from tlt_common.config_schema import load_yaml
from tlt_common.mission.schema import load_mission

MISSION = load_mission(REPO_ROOT / "missions" / "one_bay.yaml")
MEMBER = MISSION.member("bay1/vertical/x0_y0")
JOINT = next(r.joint for r in MEMBER.rivets if r.step == "affix")
S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class Scripted(Action):
    """Answers SUCCESS (or ``status``) and counts its runs: a motion, the gun, the jaws."""

    def __init__(self, name: str, status: Status = S) -> None:
        super().__init__(name)
        self.status_to_give = status
        self.runs = 0

    def update(self) -> Status:
        self.runs += 1
        return self.status_to_give


def _config(**verify):
    raw = load_yaml(default_config_path("ars_x"))
    raw["mission"] = "missions/one_bay.yaml"
    raw["timeouts"].update(server_s=1.0, service_s=3.0)
    raw["verify_joints"] = {"enabled": True, "looks": 2, "reshots": 1, **verify}
    return ars_config_from_dict(raw)


def _ctx(node=None, **verify):
    data = RequestData(request=Request("affix_member", MEMBER.id, "ars_x"), member=MEMBER)
    kept = []
    ctx = SimpleNamespace(
        node=node,
        config=_config(**verify),
        mission=MISSION,
        scene=load_scene_config(),
        ars="ars_x",
        data=data,
        clock=time.monotonic,
        arm_q=lambda: np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0]),
        kept=kept,
    )
    ctx.keep = lambda: kept.append((ctx.data.shots, len(ctx.data.looks)))
    return ctx


def _look(verdict: str, shot: int = 1) -> JointLook:
    return JointLook(JOINT, shot, verdict, f"seen {verdict}")


# ----- leaves, without ROS -----
def test_count_shot_counts_and_keeps_or_fails_saying_why():
    ctx = _ctx()
    CountShot("Count Shot", ctx).tick_once()
    assert ctx.data.shots == 1 and ctx.kept == [(1, 0)]
    ctx.keep = lambda: "the state file /x cannot be written: disk full"
    shot = CountShot("Count Shot", ctx)
    shot.tick_once()
    assert shot.status == F and "disk full" in shot.feedback_message


def test_judged_reads_only_the_looks_since_the_last_shot():
    ctx = _ctx()
    judged = JointJudged("Joint Judged?", ctx)
    ctx.data.shots = 1
    assert judged.evaluate() is False and judged.feedback_message == "not looked at"
    ctx.data.looks = [_look("cannot_judge")]
    assert judged.evaluate() is False
    ctx.data.looks.append(_look("unseated"))
    assert judged.evaluate() is True
    ctx.data.shots = 2  # a reshot since: the old verdict says nothing of the new rivet
    assert judged.evaluate() is False


@pytest.mark.parametrize(
    ("looks", "shots", "settled", "state"),
    [
        ([], 1, True, "unverified"),  # shot, never looked at
        ([_look("good")], 1, True, "verified"),
        ([_look("cannot_judge"), _look("cannot_judge")], 1, True, "unverified"),
        ([_look("unseated")], 1, False, "failed"),
        ([_look("no_head"), _look("wrong_hole", 2)], 2, True, "failed"),
        ([_look("no_head"), _look("good", 2)], 2, True, "verified"),
        ([_look("no_head")], 2, True, "unverified"),  # shot again, killed before the look
        ([], 0, True, ""),  # never shot at here
    ],
)
def test_a_joint_is_settled_when_no_new_rivet_is_wanted_and_its_state_follows(looks, shots, settled, state):
    ctx = _ctx()
    ctx.data.looks, ctx.data.shots = list(looks), shots
    assert JointSettled("Joint Settled?", ctx, reshots=1).evaluate() is settled
    assert joint_state(ctx.data) == state


def test_a_bad_joint_wants_as_many_reshots_as_configured():
    ctx = _ctx()
    ctx.data.looks, ctx.data.shots = [_look("unseated"), _look("unseated", 2)], 2
    assert JointSettled("Joint Settled?", ctx, reshots=1).evaluate() is True
    assert JointSettled("Joint Settled?", ctx, reshots=2).evaluate() is False
    assert JointSettled("Joint Settled?", ctx, reshots=0).evaluate() is True


def test_the_joint_is_where_the_mission_puts_it_and_the_gun_side_is_the_tool_s_back():
    ctx = _ctx()
    here, along, outward = joint_geometry(ctx, JOINT)
    origin = tower_origin(ctx.scene, MISSION, MEMBER.bay)
    points = dict(MEMBER.joints)
    np.testing.assert_allclose(here, origin + np.asarray(points[JOINT]))
    other = next(p for k, p in MEMBER.joints if k != JOINT)
    np.testing.assert_allclose(
        along, (np.asarray(other) - points[JOINT]) / np.linalg.norm(np.subtract(other, points[JOINT]))
    )
    tool = ctx.scene.kinematics("ars_x").forward(ctx.arm_q())
    np.testing.assert_allclose(outward, -tool[:3, 2])
    ctx.arm_q = lambda: None
    with pytest.raises(RuntimeError, match="joint state"):
        joint_geometry(ctx, JOINT)
    with pytest.raises(RuntimeError, match="no joint"):
        joint_geometry(_ctx(), "bay9/x0_y0")


def test_the_result_reports_the_last_judged_look_with_every_verdict():
    ctx = _ctx()
    assert joint_checks(ctx.data) == []
    ctx.data.shots = 2
    ctx.data.looks = [
        _look("unseated"),
        JointLook(JOINT, 2, "good", "head seated", 0.001, -0.002, 90, (1.0, 2.0, 3.0), "ars_x/d405"),
        _look("cannot_judge", 2),
    ]
    (check,) = joint_checks(ctx.data)
    assert (check.member_id, check.joint, check.state) == (MEMBER.id, JOINT, "unverified")
    assert (check.verdict, check.shots, check.looks) == ("good", 2, 3)
    assert list(check.verdicts) == ["unseated", "good", "cannot_judge"]
    assert (check.height, check.along_offset, check.pixels) == (0.001, -0.002, 90)
    assert (check.head.x, check.head.y, check.head.z) == (1.0, 2.0, 3.0)


def test_a_joint_shot_and_never_looked_at_is_reported_unverified():
    ctx = _ctx()
    ctx.data.shots = 1
    (check,) = joint_checks(ctx.data)
    assert (check.joint, check.state, check.verdict, check.looks) == (JOINT, "unverified", "", 0)
    assert "never looked at" in check.reason


def test_shots_and_looks_are_kept_in_the_state_file(tmp_path):
    file = RequestFile(tmp_path / "ars_x.json", MISSION, "ars_x")
    data = RequestData(request=Request("affix_member", MEMBER.id, "ars_x"), member=MEMBER, recorded="affixed")
    data.shots = 2
    data.looks = [
        _look("unseated"),
        JointLook(JOINT, 2, "good", "seated", 0.001, 0.0, 80, (1.0, 2.0, 3.0), "c"),
    ]
    file.save(data)
    back = file.load()
    assert back.shots == 2 and back.looks == data.looks


# ----- with ROS: a stand-in vision -----
class StandInVision:
    """Serves VerifyJoint with ``verdicts`` in turn (the last repeats); keeps the requests."""

    def __init__(self, node: Node, verdicts: list[str]) -> None:
        self.verdicts = list(verdicts)
        self.requests: list = []
        self.service = node.create_service(VerifyJoint, ros_names.VISION_VERIFY_JOINT, self._answer)

    def _answer(self, request, response):
        self.requests.append(request)
        verdict = self.verdicts.pop(0) if len(self.verdicts) > 1 else self.verdicts[0]
        response.verdict, response.reason = verdict, f"stand-in says {verdict}"
        if verdict != "cannot_judge":
            response.pixels, response.height = 100, 0.004 if verdict == "unseated" else 0.0
        return response


@pytest.fixture
def ros():
    context = rclpy.Context()
    rclpy.init(context=context)
    ars = Node("ars_x_joint_test", context=context)
    vision = Node("vision_stand_in", context=context)
    executor = MultiThreadedExecutor(context=context)
    executor.add_node(ars)
    executor.add_node(vision)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    yield SimpleNamespace(ars=ars, vision=vision)
    executor.shutdown()
    ars.destroy_node()
    vision.destroy_node()
    rclpy.try_shutdown(context=context)
    thread.join(timeout=5)


def _run(behaviour, limit_s: float = 20.0) -> Status:
    deadline = time.monotonic() + limit_s
    behaviour.tick_once()
    while behaviour.status == R and time.monotonic() < deadline:
        time.sleep(0.01)
        behaviour.tick_once()
    return behaviour.status


def test_look_at_joint_asks_where_the_model_puts_the_joint_and_keeps_the_verdict(ros):
    vision = StandInVision(ros.vision, ["unseated"])
    ctx = _ctx(ros.ars)
    ctx.data.shots = 1
    look = LookAtJoint("Look At Joint", ctx, JOINT)
    assert _run(look) == S
    (asked,) = vision.requests
    here, along, outward = joint_geometry(ctx, JOINT)
    np.testing.assert_allclose([asked.joint.x, asked.joint.y, asked.joint.z], here)
    np.testing.assert_allclose([asked.along.x, asked.along.y, asked.along.z], along)
    np.testing.assert_allclose([asked.outward.x, asked.outward.y, asked.outward.z], outward)
    assert asked.camera == "ars_x/d405" and asked.joint_id == f"{MEMBER.id}@{JOINT}"
    (seen,) = ctx.data.looks
    assert (seen.shot, seen.verdict, seen.height, seen.pixels) == (1, "unseated", 0.004, 100)
    assert ctx.kept[-1] == (1, 1)


def test_a_vision_that_is_not_there_is_a_look_that_could_not_judge_not_a_failure(ros):
    ctx = _ctx(ros.ars)
    look = LookAtJoint("Look At Joint", ctx, JOINT)
    assert _run(look) == S
    (seen,) = ctx.data.looks
    assert seen.verdict == "cannot_judge" and "not available" in seen.reason
    assert joint_state(ctx.data) == "unverified"


def _shot(ros, monkeypatch, verdicts, **verify):
    """Rivet Member of an affix shot, its motions, gun, jaws and records scripted."""
    vision = StandInVision(ros.vision, verdicts)
    ctx = _ctx(ros.ars, **verify)
    made: dict[str, list[Scripted]] = {}

    def scripted(name, *args, **kwargs):
        leaf = Scripted(name if isinstance(name, str) else "Release")
        made.setdefault(leaf.name, []).append(leaf)
        return leaf

    for name in ("MarkSetting", "FireRivetGun", "RecordMember", "Settle", "release"):
        monkeypatch.setattr(subtrees, name, scripted)
    builder = SubtreeBuilder(ctx, planner=None)
    builder._move = lambda name, goal: scripted(name)
    loads: list[bool] = []

    def load_rivet(dispenser, *, look_first=False):
        loads.append(look_first)
        return scripted("Load Rivet")

    builder.load_rivet = load_rivet
    tree = builder.rivet_member("rivet", record="affixed", member=MEMBER, joint=JOINT)
    status = _run(tree, 30.0)
    loaded = sum(leaf.runs for leaf in made.get("Load Rivet", []))
    return SimpleNamespace(
        status=status, ctx=ctx, vision=vision, made=made, loads=loads, loaded=loaded, tree=tree
    )


def test_a_good_joint_costs_one_look_and_nothing_else(ros, monkeypatch):
    shot = _shot(ros, monkeypatch, ["good"])
    assert shot.status == S
    assert len(shot.vision.requests) == 1 and shot.loaded == 0
    assert [c.name for c in shot.tree.children][:5] == [
        "Mark Shot", "Count Shot", "Fire Rivet Gun", "Record Affixed", "Verify Joint"
    ]  # fmt: skip
    assert joint_state(shot.ctx.data) == "verified" and shot.ctx.data.shots == 1


def test_a_joint_vision_cannot_judge_is_looked_at_again_then_left_unverified(ros, monkeypatch):
    shot = _shot(ros, monkeypatch, ["cannot_judge"], looks=3)
    assert shot.status == S
    assert len(shot.vision.requests) == 3 and shot.loaded == 0
    assert joint_state(shot.ctx.data) == "unverified"


def test_a_bad_joint_gets_a_new_rivet_looked_into_the_gun_first_and_is_looked_at_again(ros, monkeypatch):
    shot = _shot(ros, monkeypatch, ["cannot_judge", "wrong_hole", "good"])
    assert shot.status == S
    assert [look.verdict for look in shot.ctx.data.looks] == ["cannot_judge", "wrong_hole", "good"]
    assert [look.shot for look in shot.ctx.data.looks] == [1, 1, 2]
    assert shot.loads == [True]  # a misfire leaves its rivet in the gun: looked for first
    assert shot.loaded == 1
    assert len(shot.made["Fire Rivet Gun"]) == 2 and shot.ctx.data.shots == 2
    assert joint_state(shot.ctx.data) == "verified"


def test_a_joint_still_bad_after_its_reshots_is_reported_failed_and_the_request_still_succeeds(
    ros, monkeypatch
):
    shot = _shot(ros, monkeypatch, ["no_head"])
    assert shot.status == S  # the member is set: the CRS decides on the joint
    assert shot.ctx.data.shots == 2 and shot.loaded == 1
    (check,) = joint_checks(shot.ctx.data)
    assert (check.state, check.verdict, list(check.verdicts)) == ("failed", "no_head", ["no_head", "no_head"])


def test_a_request_finished_after_a_restart_looks_at_a_joint_shot_and_never_looked_at(ros):
    ctx = _ctx(ros.ars)
    ctx.data.shots = 1
    builder = SubtreeBuilder(ctx, planner=None)
    builder._move = lambda name, goal: Scripted(name)
    assert [c.name for c in builder.finish("affix_member", MEMBER).children] == ["Verify Joint", "Retreat"]
    ctx.data.looks = [_look("good")]
    assert [c.name for c in builder.finish("affix_member", MEMBER).children] == ["Retreat"]


def test_verification_is_for_struts_and_switched_by_the_ars_file():
    ctx = _ctx(enabled=False)
    builder = SubtreeBuilder(ctx, planner=None)
    assert builder.checked_joint(MEMBER, JOINT) == ""
    foundation = next(m for m in MISSION.members if m.kind == "foundation_rivet")
    assert SubtreeBuilder(_ctx(), planner=None).checked_joint(foundation, foundation.joints[0][0]) == ""
    assert SubtreeBuilder(_ctx(), planner=None).checked_joint(MEMBER, JOINT) == JOINT
