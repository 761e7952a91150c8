"""Whole CRS requests against an ARS on the real hardware path (tests/tlt_ars/conftest.py): the
UR emulator and driver, the Dynamixel EE emulator and driver, ground-truth vision and CRS
stand-ins. The tests share one stack and run in file order (the mission state carries over)."""

from __future__ import annotations

import threading
import time

import numpy as np
import py_trees
import pytest
from action_msgs.msg import GoalStatus
from tlt_interfaces.action import AddMember
from tlt_interfaces.srv import GroundCommand

from tlt_ars.mission_state import Request
from tlt_ars.motion import ExecuteTrajectory, TrajectorySlot
from tlt_ars.motion_planner import MotionGoal
from tlt_ars.planning.planner import PlanningFailed
from tlt_ars.planning.targets import part_in_tool, placement_targets
from tlt_ars.planning.world import tower_origin
from tlt_ars.tree import failure_reason
from tlt_common.geometry.transforms import pose_error

pytestmark = pytest.mark.timeout(240)
VERTICAL, DIAGONAL = AddMember.Goal.KIND_VERTICAL, AddMember.Goal.KIND_DIAGONAL


def add_member(stack, member_id: str, kind: int, feedback=None):
    member = stack.mission.member(member_id)
    return stack.send(
        "add_member",
        feedback,
        kind=kind,
        bay=member.bay,
        member_id=member_id,
        position=member.position,
        ars="ars_x",
    )


def test_add_cross_frame_corrects_a_misalignment_and_verifies_the_placement(stack):
    stack.world.grasp_offset = np.array([0.008, 0.0, 0.0])  # the frame sits 8 mm off in the gripper
    before = stack.ars.ctx.state.remaining["cross_frame_dispenser"]
    feedback = []
    handle = stack.send("add_cross_frame", feedback, bay=1, member_id="bay1/cross_frame", ars="ars_x")
    result = stack.result(handle)
    assert result.status == GoalStatus.STATUS_SUCCEEDED, result.result.reason
    steps = {f.step for f in feedback}
    assert any("Correct Alignment/Correct Pose" in s for s in steps)
    # Placed where it belongs: the ground-truth part pose is within the alignment tolerance.
    part = stack.world.part_pose
    member = stack.mission.member("bay1/cross_frame")
    assert (
        min(
            pose_error(part, t.pose)[0]
            for t in placement_targets(stack.scene, stack.mission, member, "ars_x")
        )
        < 0.005
    )
    assert stack.ars.ctx.state.is_placed("bay1/cross_frame")
    assert stack.ars.ctx.state.remaining["cross_frame_dispenser"] == before - 1


def test_add_member_vertical_loads_rivet_grabs_inspects_places_and_rivets(stack):
    feedback = []
    state = stack.ars.ctx.state
    rivets, struts = state.remaining["rivet_dispenser_x"], state.remaining["vertical_dispenser_x"]
    fired = len(stack.gpio.fired)
    # The first presentation is not inspected, the second not judged: shown again each time, kept.
    stack.inspection_verdicts[:] = [None, stack.CANNOT_JUDGE]
    handle = add_member(stack, "bay1/vertical/x0_y0", VERTICAL, feedback)
    assert handle.accepted  # the acknowledgement
    result = stack.result(handle)
    assert result.status == GoalStatus.STATUS_SUCCEEDED, result.result.reason
    assert result.result.success and result.result.reason == "" and result.result.parts_discarded == 0
    steps = [f.step for f in feedback]
    # Feedback names the running leaf of each subtree of Fig. 32, in order, with growing progress.
    firsts = [next(i for i, s in enumerate(steps) if s.startswith(f"Add Member/{sub}")) for sub in
              ("Load Rivet", "Get Inspected Member", "Place Member", "Rivet Member")]  # fmt: skip
    assert firsts == sorted(firsts)
    assert any(s.startswith("Add Member/Load Rivet/Approach Rivet Dispenser/") for s in steps)
    assert any("/Grab Member/Set Width Beside Approach/Approach/Approach Dispenser/" in s for s in steps)
    assert any("/Inspect Member/Move To Inspection/" in s for s in steps)
    progress = [f.progress for f in feedback]
    assert progress == sorted(progress) and 0 < progress[-1] < 1
    assert state.is_placed("bay1/vertical/x0_y0")
    assert state.remaining["rivet_dispenser_x"] == rivets - 1
    assert state.remaining["vertical_dispenser_x"] == struts - 1
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"]  # the rivet gun fired once, through GPIO
    assert stack.world.held is None and not stack.ee_states[-1].part_grasped
    assert stack.inspections[-3:] == ["bay1/vertical/x0_y0"] * 3
    assert any(f.step.endswith("/Inspect Member/Present Part") for f in feedback)


def test_add_member_diagonal_extends_width_and_replaces_a_part_that_fails_inspection(stack):
    """The diagonal is placed where it belongs: held off its middle, with its middle on the middle
    of its joints (vision reports the part's own frame)."""
    state = stack.ars.ctx.state
    before = state.remaining["diagonal_dispenser_x"]
    stack.inspection_verdicts[:] = [False]  # the CRS fails the first part
    # The width as the request starts: on a loaded machine its first feedback can come before the
    # next EE state, and the width at the first Load Rivet step would go unrecorded.
    widths = [stack.width()]

    def record(state) -> None:
        widths.append(state.position[2])

    stack.ee_listeners.append(record)
    steps = []  # (step, the width when its first feedback came)

    def feedback(f) -> None:
        if not steps or steps[-1][0] != f.step:
            steps.append((f.step, widths[-1]))

    try:
        handle = add_member(stack, "bay1/diagonal/face_x0", DIAGONAL, feedback)
        result = stack.result(handle, timeout=180)  # two parts fetched and inspected, one discarded
    finally:
        stack.ee_listeners.remove(record)
    assert result.status == GoalStatus.STATUS_SUCCEEDED, result.result.reason
    assert result.result.parts_discarded == 1
    assert state.remaining["diagonal_dispenser_x"] == before - 2  # the discarded part and its replacement
    assert state.discarded["diagonal_dispenser_x"] == 1
    assert stack.inspections[-2:] == ["bay1/diagonal/face_x0"] * 2
    assert max(widths) == pytest.approx(0.02, abs=0.002)  # extended before the grasp
    # ... commanded ahead, so it extends while the rivet is loaded: narrow as the loading began,
    # out by the time the jaws opened and the arm approached the dispenser.
    loading = [w for step, w in steps if "/Load Rivet/" in step]
    assert loading and loading[0] < 0.005 and max(loading) > 0.015, steps
    beside = [w for step, w in steps if "/Grab Member/Extend Width Beside Approach/Approach/" in step]
    assert beside and beside[0] > 0.015, steps
    # Retracted after the rivet: commanded as the request's last step, and not waited for.
    stack.wait(lambda: abs(stack.width()) <= 0.002, "the width retracted after the request")
    middle = (stack.world.part_pose @ part_in_tool(stack.mission, "diagonal"))[:3, 3]
    joints = [np.asarray(p) for _, p in stack.mission.member("bay1/diagonal/face_x0").joints]
    origin = tower_origin(stack.scene, stack.mission, 1)
    assert np.linalg.norm(middle - origin - (joints[0] + joints[1]) / 2) < 0.005


def test_a_slide_moving_on_a_command_the_ars_never_sent_is_planned_over_its_whole_travel(stack):
    """An ARS restarted while its width slide moves (a Retract Width is not waited for) does not
    know where the slide goes: a motion is planned as if it went to the end it moves towards."""
    from std_msgs.msg import Float64MultiArray

    ctx = stack.ars.ctx
    # The request before retracts the slide without waiting for it, and waits for it itself only
    # if its other checks passed.
    stack.wait(lambda: abs(stack.width()) <= 0.002, "the slide back at 0 after the request before")
    assert ctx.planning_width() == pytest.approx(0.0, abs=0.002)
    target, ctx.width_target = ctx.width_target, None  # as after a restart
    try:
        ctx.width_publisher.publish(Float64MultiArray(data=[0.02]))  # sent by the ARS that died
        seen = []

        def planned(moving: bool) -> bool:
            seen.append(ctx.planning_width())
            return isinstance(seen[-1], tuple) == moving and seen[-1] is not None

        stack.wait(lambda: planned(True), "a width planned over the slide's move")
        assert 0.0 <= seen[-1][0] < 0.02 and seen[-1][1] == 0.02  # the widest the config sends it to
        stack.wait(lambda: planned(False) and abs(seen[-1] - 0.02) < 0.002, "the slide standing at 0.02 m")
    finally:
        ctx.width_publisher.publish(Float64MultiArray(data=[0.0]))
        stack.wait(lambda: abs(stack.width()) <= 0.002, "the slide back at 0")
        ctx.width_target = target


def protective_stop_in(stack, member_id: str, kind: int, motion: str) -> None:
    """Add ``member_id`` with a protective stop as the arm starts the motion ``motion`` (a path
    below the branch, e.g. ``Rivet Member/Retreat``): the request fails there."""
    ctx = stack.ars.ctx
    planning_s = ctx.config.timeouts["planning_s"]
    ctx.config.timeouts["planning_s"] = 3.0  # how long each attempt waits for the stopped arm
    stopped = []

    def stop(feedback) -> None:
        if not stopped and f"/{motion}/" in feedback.step and "Execute" in feedback.step:
            stopped.append(feedback.step)
            stack.emulator.call("protective_stop", f"the test's protective stop in {motion}")

    try:
        result = stack.result(add_member(stack, member_id, kind, stop), timeout=180)
    finally:
        ctx.config.timeouts["planning_s"] = planning_s
    assert stopped, f"the request never reached {motion}"
    assert result.status == GoalStatus.STATUS_ABORTED
    assert motion in result.result.reason, result.result.reason


def test_a_request_failed_after_its_rivet_is_finished_by_the_same_request_sent_again(stack):
    """A protective stop during the Retreat after the rivet fails the request with the diagonal
    riveted and the arm at the tower, and the ARS is then restarted (killed, say, before the CRS
    cleared its fault): the new ARS knows the member only from its state file, since the CRS never
    heard the result. The CRS's retry of the same request is not run afresh nor refused as already
    placed: the ARS lets go, retreats, retracts the width and reports success, without another
    rivet or part; asked once more (a success the CRS never heard), it answers success again."""
    state, ctx = stack.ars.ctx.state, stack.ars.ctx
    member = "bay1/diagonal/face_y0"
    protective_stop_in(stack, member, DIAGONAL, "Rivet Member/Retreat")
    assert state.is_placed(member)
    retreat = ctx.data.targets["place"].pre_pose

    stack.emulator.call("unlock_protective_stop")
    stack.restart_ars(unheard=member)
    state = stack.ars.ctx.state
    assert state.is_placed(member)  # from the state file alone
    fired = len(stack.gpio.fired)
    left = (state.remaining["diagonal_dispenser_x"], state.remaining["rivet_dispenser_x"])
    for _ in range(2):
        feedback = []
        again = stack.result(add_member(stack, member, DIAGONAL, feedback))
        assert again.status == GoalStatus.STATUS_SUCCEEDED, again.result.reason
        assert again.result.parts_discarded == 0
        assert {f.step.split("/")[0] for f in feedback} == {"Finish Add Member"}
        assert len(stack.gpio.fired) == fired  # no second rivet
        assert (state.remaining["diagonal_dispenser_x"], state.remaining["rivet_dispenser_x"]) == left
        stack.wait(lambda: abs(stack.width()) <= 0.002, "the width retracted after the retreat")
        assert pose_error(stack.world.tool(), retreat)[0] < 0.01  # at the pre-pose of its placement


def test_empty_dispenser_fails_the_request_with_that_reason(stack):
    state = stack.ars.ctx.state
    state.remaining["vertical_dispenser_x"] = 1  # one part left, and it fails inspection
    stack.world.remaining["vertical_dispenser_x"] = 1
    stack.inspection_verdicts[:] = [False]
    result = stack.result(add_member(stack, "bay1/vertical/x0_y1", VERTICAL))
    assert result.status == GoalStatus.STATUS_ABORTED
    assert not result.result.success
    assert "dispenser 'vertical_dispenser_x' is empty" in result.result.reason
    assert "Dispenser Has Parts?" in result.result.reason
    assert result.result.parts_discarded == 1
    assert state.remaining["vertical_dispenser_x"] == 0
    assert not state.is_placed("bay1/vertical/x0_y1")
    state.remaining["vertical_dispenser_x"] = stack.world.remaining["vertical_dispenser_x"] = 3  # refilled


def test_a_part_and_a_rivet_left_by_a_failed_request_are_dealt_with_before_the_next_one_moves(stack):
    """A protective stop on the way to inspection fails the request with a vertical in the jaws
    and a rivet in the gun, and the ARS is then restarted: the new one knows both from its state
    file. The request sent again first takes the held part to the discard pose and lets go of it
    there (counted discarded); then the camera finds the rivet still in the gun, so the gun does
    not go to the feeder again, and the request goes for a new part."""
    member = "bay1/vertical/x0_y1"
    protective_stop_in(stack, member, VERTICAL, "Inspect Member/Move To Inspection")
    assert stack.world.held == "vertical_dispenser_x" and stack.world.rivet_loaded

    stack.emulator.call("unlock_protective_stop")
    stack.restart_ars(unheard=member)
    state, data = stack.ars.ctx.state, stack.ars.ctx.data
    assert data.holding == "vertical" and data.rivet_in_gun  # from the state file
    discarded = state.discarded["vertical_dispenser_x"]
    feedback = []
    handle = add_member(stack, member, VERTICAL, feedback)
    part_next = "Add Member/Get Inspected Member/"
    stack.wait(lambda: any(f.step.startswith(part_next) for f in feedback), "a new part next", 120)
    steps = [f.step for f in feedback]
    assert steps[0].startswith("Add Member/Discard Held Part/"), steps[0]
    assert any(s.startswith("Add Member/Load Rivet/Rivet Still Loaded?") for s in steps), steps
    assert not any("Load Another Rivet" in s for s in steps), steps
    assert stack.world.held is None
    discard = stack.scene.kinematics("ars_x").forward(stack.ars.config.discard_pose.joints)
    assert np.linalg.norm(stack.world.part_pose[:3, 3] - discard[:3, 3]) < 0.05  # let go of there
    assert state.discarded["vertical_dispenser_x"] == discarded + 1 and stack.ars.ctx.data.holding is None
    handle.cancel_goal_async()
    result = stack.result(handle)
    assert result.status == GoalStatus.STATUS_CANCELED
    # the CRS counts the held part against the dispenser the result names
    assert list(result.result.discarded_from) == ["vertical_dispenser_x"]
    assert result.result.parts_discarded == 1
    state.remaining["vertical_dispenser_x"] = stack.world.remaining["vertical_dispenser_x"] = 3  # refilled


def strut(member_id: str, bay: int = 1, kind: int = VERTICAL, ars: str = "ars_x") -> dict:
    return dict(kind=kind, bay=bay, member_id=member_id, position=member_id.rsplit("/", 1)[-1], ars=ars)


@pytest.mark.parametrize(
    ("request_kind", "fields", "reason"),
    [
        ("add_member", strut("bay1/vertical/x9_y9"), "unknown member 'bay1/vertical/x9_y9'"),
        ("add_member", strut("bay2/vertical/x0_y0", bay=2), "bay 2 has not started"),
        ("add_member", strut("bay1/vertical/x0_y0"), "already placed"),
        ("add_member", strut("bay1/vertical/x1_y0", kind=DIAGONAL), "is a vertical"),
        ("add_member", strut("bay1/vertical/x1_y0", ars="ars_y"), "addressed to 'ars_y'"),
        ("add_member", strut("bay1/vertical/x1_y1"), "is for 'ars_y' to add, not 'ars_x'"),
        ("affix_member", strut("bay1/vertical/x1_y1"), "is for 'ars_y' to affix, not 'ars_x'"),
        ("add_cross_frame", dict(bay=1, member_id="bay1/cross_frame", ars="ars_x"), "already placed"),
        ("foundation_rivet", dict(joint_id="foundation/x0_y0", ars="ars_x"), "bay 2 has not started"),
    ],
)
def test_bad_requests_are_refused_with_a_reason_and_nothing_moves(stack, request_kind, fields, reason):
    q = stack.ars.ctx.arm_q()
    result = stack.result(stack.send(request_kind, None, **fields), timeout=10)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert not result.result.success and reason in result.result.reason
    assert result.result.reason.startswith("rejected: ")
    assert np.allclose(stack.ars.ctx.arm_q(), q, atol=1e-3)


def test_concurrent_goal_rejected_pause_holds_resume_continues_cancel_stops(stack):
    feedback = []
    first = add_member(stack, "bay1/vertical/x1_y0", VERTICAL, feedback)
    stack.wait(lambda: any("/Execute " in f.step for f in feedback), "the arm moving")
    second = stack.result(
        stack.send("add_cross_frame", None, bay=1, member_id="bay1/cross_frame", ars="ars_x"), 10
    )
    assert second.status == GoalStatus.STATUS_ABORTED
    assert "busy: ars_x is running add_member for 'bay1/vertical/x1_y0'" in second.result.reason

    def speed():
        return float(np.max(np.abs(stack.ars.ctx.arm_velocity())))

    stack.wait(lambda: speed() > 0.2, "the arm at speed")
    assert stack.ground_command(GroundCommand.Request.PAUSE).accepted
    stack.wait(lambda: speed() < 0.01, "the arm held", timeout=5)
    stack.wait(stack.arm_standing_still, "the arm settled", timeout=5)
    q = stack.ars.ctx.arm_q()
    time.sleep(0.5)
    assert np.allclose(stack.ars.ctx.arm_q(), q, atol=2e-3)  # paused: the tree does not tick
    assert not stack.ground_command(GroundCommand.Request.PAUSE).accepted  # already paused
    assert stack.ground_command(GroundCommand.Request.RESUME).accepted
    stack.wait(lambda: speed() > 0.2, "the arm moving again after Resume")

    cancel = first.cancel_goal_async()
    stack.wait(cancel.done, "cancel response")
    result = stack.result(first, timeout=20)
    assert result.status == GoalStatus.STATUS_CANCELED
    assert "arm is stopped" in result.result.reason
    stack.wait(stack.arm_standing_still, "the arm settled", timeout=5)
    q = stack.ars.ctx.arm_q()
    time.sleep(0.5)
    assert np.allclose(stack.ars.ctx.arm_q(), q, atol=2e-3)  # it stays where it stopped
    assert not stack.ars.ctx.state.is_placed("bay1/vertical/x1_y0")
    assert stack.ars.active is None
    assert not any(stack.gpio.outputs.values())  # no rivet gun left firing


def _paused_while_presenting(stack, member: str, paused_s: float) -> tuple[int, object]:
    """Add ``member``; while its part is presented (the CRS stand-in holding the call), Pause, let
    the stand-in answer 0.5 s later, Resume after ``paused_s``. Returns how many presentations
    there had been when paused, and the request's result."""
    stack.inspection_gate = threading.Event()
    try:
        handle = add_member(stack, member, VERTICAL)
        stack.wait(lambda: stack.inspections[-1:] == [member], "the part presented", timeout=60)
        presented = len(stack.inspections)
        assert stack.ground_command(GroundCommand.Request.PAUSE).accepted
        time.sleep(0.5)
        stack.inspection_gate.set()  # the answer comes while the ARS is paused
        time.sleep(paused_s - 0.5)
        assert stack.ground_command(GroundCommand.Request.RESUME).accepted
        return presented, stack.result(handle)
    finally:
        stack.inspection_gate.set()
        stack.inspection_gate = None


def test_a_part_presented_when_paused_is_judged_once_by_the_answer_to_its_call(stack):
    """The CRS answers while the ARS is paused (a CRS fault holds the build and pauses the ARS
    mid-inspection): the call is kept, so its verdict is read on Resume; a call given up and made
    again would have its verdict sent to the call given up."""
    member = "bay1/vertical/x1_y0"
    presented, result = _paused_while_presenting(stack, member, 1.0)
    assert result.status == GoalStatus.STATUS_SUCCEEDED, result.result.reason
    assert len(stack.inspections) == presented  # judged by the answer to its one call
    assert stack.ars.ctx.state.is_placed(member)


def test_time_paused_does_not_count_toward_presenting_a_part(stack):
    """An operator's Pause while the part is presented, longer than ``present_part_s``: the CRS
    answers meanwhile that it did not inspect the part, and after Resume the ARS presents it again
    (the request does not fail for the time it stood paused)."""
    member = "bay1/vertical/x0_y1"
    timeouts = stack.ars.ctx.config.timeouts
    limit = timeouts["present_part_s"]
    timeouts["present_part_s"] = 3.0
    stack.inspection_verdicts = [None]  # not inspected, then passed
    try:
        presented, result = _paused_while_presenting(stack, member, 4.5)
    finally:
        stack.inspection_verdicts = []
        timeouts["present_part_s"] = limit
    assert result.status == GoalStatus.STATUS_SUCCEEDED, result.result.reason
    assert len(stack.inspections) == presented + 1  # presented again once, and judged
    assert stack.ars.ctx.state.is_placed(member)


def test_affix_member_loads_and_places_a_rivet(stack):
    fired = len(stack.gpio.fired)
    fields = strut("bay1/vertical/x0_y0")
    result = stack.result(stack.send("affix_member", None, **fields))
    assert result.status == GoalStatus.STATUS_SUCCEEDED, result.result.reason
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"]
    # Sent again (the CRS never heard the success): finished, not riveted twice.
    feedback = []
    again = stack.result(stack.send("affix_member", feedback, **fields))
    assert again.status == GoalStatus.STATUS_SUCCEEDED, again.result.reason
    assert {f.step.split("/")[0] for f in feedback} == {"Finish Affix Member"}
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"]


def test_foundation_rivet_subtree_ticks_on_its_own(stack):
    """Fig. 38 built from its parameters and ticked by itself, outside the request machinery (the
    mission's foundation rivets come after bay 2, which the ARS refuses to start in this test)."""
    ctx = stack.ars.ctx
    member = stack.mission.member("foundation/x0_y0")
    assert stack.ars.active is None  # the ARS's own tree idles in Wait For Request meanwhile
    ctx.begin(Request("foundation_rivet", member.id, "ars_x"))
    tree = py_trees.trees.BehaviourTree(stack.ars.tree.builder.foundation_rivet(member))
    fired = len(stack.gpio.fired)
    deadline = time.monotonic() + 120
    while tree.root.status in (py_trees.common.Status.INVALID, py_trees.common.Status.RUNNING):
        assert time.monotonic() < deadline, "subtree did not finish"
        tree.tick()
        time.sleep(0.05)
    assert tree.root.status == py_trees.common.Status.SUCCESS, failure_reason(tree.root)
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"]
    assert ctx.state.is_riveted("foundation/x0_y0")


def test_a_trajectory_planned_from_elsewhere_is_never_sent(stack):
    ctx = stack.ars.ctx
    # Where the arm stands, not where the last test's motion still carries it (a clean clone's
    # loaded arm moved on 7 mrad after this was read).
    stack.wait(stack.arm_standing_still, "the arm settled", timeout=10)
    q = ctx.arm_q()
    stale = None
    # A short move that starts away from the arm; which way is free depends on where the tests
    # before left the arm.
    moves = [(j, sign * size) for size in (1.0, 0.3) for j in (0, 5, 4, 3, 1, 2) for sign in (1.0, -1.0)]
    for joint, sign in moves:
        step = np.zeros(6)
        step[joint] = sign
        try:
            stale = stack.ars.planner.plan(
                q + 0.3 * step, MotionGoal(joints=q + 0.4 * step),
                placed=ctx.state.placed(), bay=1, carrying=None, other_q=None,
            )  # fmt: skip
            break
        except PlanningFailed:
            continue
    assert stale is not None, "no free short move near the arm to plan"
    slot = TrajectorySlot()
    slot.motion = stale
    execute = ExecuteTrajectory("Execute Stale", ctx, slot)
    deadline = time.monotonic() + 10
    execute.tick_once()
    while execute.status == py_trees.common.Status.RUNNING:
        assert time.monotonic() < deadline
        time.sleep(0.05)
        execute.tick_once()
    assert execute.status == py_trees.common.Status.FAILURE
    assert "rad from where this trajectory was planned from" in execute.feedback_message
    assert np.allclose(ctx.arm_q(), q, atol=1e-3)


def resend_after_restart(stack, unheard: str, kept: tuple[str, str | None], request: str, fields: dict):
    """Restart the ARS (the CRS never heard ``unheard``'s result), check that its state file kept
    ``kept`` (what the step left in doubt sets, the part held), and send ``request`` again: it
    succeeds by its Finish branch alone. Returns the result and the steps its feedback named."""
    stack.restart_ars(unheard=unheard)
    data = stack.ars.ctx.data
    assert (data.setting, data.holding) == kept  # from the state file alone
    feedback = []
    again = stack.result(stack.send(request, feedback, **fields))
    assert again.status == GoalStatus.STATUS_SUCCEEDED, again.result.reason
    steps = [f.step for f in feedback]
    finish = "Finish " + " ".join(word.capitalize() for word in request.split("_"))
    assert {s.split("/")[0] for s in steps} == {finish}, steps
    return again, steps


def test_a_cross_frame_let_go_of_in_doubt_is_looked_for_again_and_never_fetched_again(stack):
    """Bay 2's cross frame is let go of at its place, and the EE cameras then read it 2 cm off: the
    request fails with the frame in the tower, unrecorded. The ARS is then restarted (as if killed
    right after letting go): its state file says only that it let go of the frame there. The CRS's
    retry does not fetch another frame for a place that may be taken: with the arm still there, the
    open jaws open, the frame is looked for again, seen in place and recorded, and the arm retreats."""
    stack.tell({m.id for m in stack.mission.bay_members(1)})  # the CRS: bay 1 stands, bay 2 begins
    member, state = "bay2/cross_frame", stack.ars.ctx.state

    def misread_after_release(feedback) -> None:
        if "/Let Go At Place/Release" in feedback.step and not misread:
            misread.append(feedback.step)
            stack.misread_alignments = 1

    misread = []
    fields = dict(bay=2, member_id=member, ars="ars_x")
    result = stack.result(stack.send("add_cross_frame", misread_after_release, **fields), timeout=180)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert "Let Go At Place/Placed?: misaligned: 2" in result.result.reason, result.result.reason
    assert stack.world.held is None and not state.is_placed(member)
    released_at = stack.world.part_pose.copy()
    left = state.remaining["cross_frame_dispenser"]

    _, steps = resend_after_restart(stack, member, ("placed", None), "add_cross_frame", fields)
    assert any("/Let Go At Place/Verify Placement/" in s for s in steps)
    state = stack.ars.ctx.state
    assert state.is_placed(member) and state.remaining["cross_frame_dispenser"] == left
    np.testing.assert_allclose(stack.world.part_pose, released_at)  # untouched since it was let go of


def test_a_shot_in_doubt_is_fired_again_where_it_was_fired_and_the_member_never_discarded(stack):
    """The gun's output does not switch off after the rivet of bay 2's vertical x1_y0 fired: the
    request fails with the member riveted and held, and unrecorded. The ARS is then restarted (as
    if killed while firing): its state file says only that the gun was told to fire, and from
    where. The CRS's retry neither discards the held member (it would tear it out of the tower) nor
    fetches another: with the arm still there, the gun fires again (empty), the member is recorded,
    let go of where it stands, and the arm retreats."""
    member = "bay2/vertical/x1_y0"
    fields = strut(member, bay=2)
    state = stack.ars.ctx.state
    fired = len(stack.gpio.fired)
    stack.gpio.failing_offs = 1
    result = stack.result(stack.send("add_member", None, **fields), timeout=180)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert "Rivet Member/Fire Rivet Gun: rivet gun refused" in result.result.reason, result.result.reason
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"] and not stack.world.rivet_loaded  # riveted
    assert stack.world.held == "vertical_dispenser_x" and not state.is_placed(member)
    fired_from = stack.world.tool()
    left = (state.remaining["vertical_dispenser_x"], state.remaining["rivet_dispenser_x"])

    again, steps = resend_after_restart(stack, member, ("placed", "vertical"), "add_member", fields)
    assert any(s.endswith("/Fire Rivet Gun") for s in steps) and not any("Discard" in s for s in steps)
    assert again.result.parts_discarded == 0
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"] * 2  # the second shot, with no rivet
    state = stack.ars.ctx.state
    assert state.is_placed(member) and stack.ars.ctx.data.holding is None
    assert stack.world.held is None  # let go of where it was riveted:
    assert np.linalg.norm(stack.world.part_pose[:3, 3] - fired_from[:3, 3]) < 0.005
    assert (state.remaining["vertical_dispenser_x"], state.remaining["rivet_dispenser_x"]) == left


@pytest.mark.parametrize(
    ("request_", "member", "record"),
    [
        ("affix_member", "bay2/vertical/x0_y0", "affixed"),  # ARS X's near vertical, affixed by itself
        ("foundation_rivet", "foundation/x0_y1", "riveted"),  # x0_y0 was riveted by its subtree above
    ],
)
def test_a_rivet_shot_in_doubt_is_fired_again_and_no_rivet_loaded_for_it(stack, request_, member, record):
    """The same for AffixMember and Foundation Rivet: the gun's output does not switch off after
    the rivet fired, and the ARS is restarted; its state file says the gun was told to fire, and
    from where. The CRS's retry does not load another rivet for a hole that may be riveted: with
    the arm still there the gun fires again (empty), the member is recorded, and the arm retreats."""
    state = stack.ars.ctx.state
    if request_ == "affix_member":
        stack.tell(state.placed() | {member})  # placed, as far as the ARS is concerned
        fields = strut(member, bay=2)
    else:
        stack.tell({m.id for bay in (1, 2) for m in stack.mission.bay_members(bay)})  # the tower stands
        fields = dict(joint_id=member, ars="ars_x")
    fired = len(stack.gpio.fired)
    stack.gpio.failing_offs = 1
    result = stack.result(stack.send(request_, None, **fields), timeout=180)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert "Fire Rivet Gun: rivet gun refused" in result.result.reason, result.result.reason
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"] and not stack.world.rivet_loaded
    rivets = state.remaining["rivet_dispenser_x"]

    # the CRS knows the member placed; only the rivet went unheard
    _, steps = resend_after_restart(stack, "", (record, None), request_, fields)
    assert any(s.endswith("/Fire Rivet Gun") for s in steps) and not any("Load Rivet" in s for s in steps)
    assert stack.gpio.fired[fired:] == ["rivet_gun_left"] * 2  # the second shot, with no rivet
    state = stack.ars.ctx.state
    assert state.remaining["rivet_dispenser_x"] == rivets
    assert "already" in state.check_request(Request(request_, member, "ars_x"))  # recorded: affixed, set


def test_stop_shuts_the_ars_down(stack):
    assert stack.ground_command(GroundCommand.Request.STOP).accepted
    stack.wait(stack.ars.finished.is_set, "the ARS shut down", timeout=10)
    assert not stack.ground_command(GroundCommand.Request.START).accepted
