"""Build Bay's subtrees (Figs. 20-25, 27) each on its own against stand-in ARS action servers and
vision services (real ROS actions and services), and their effect on the tower model."""

from __future__ import annotations

import pytest
from py_trees.common import Status

from tlt_common.mission.tower_model import INSPECTED, NOT_PLACED, PLACED, RIVETED
from tlt_crs.behaviours.actuators import Actuators
from tlt_crs.behaviours.ars_requests import SendArsRequest
from tlt_crs.tree import (
    add_cross_frame,
    add_diagonal,
    add_foundation_rivets,
    add_vertical,
    bay_test,
    build_bay,
)


def _member(ctx, member_id):
    return ctx.mission.member(member_id)


def test_far_vertical_is_added_by_ars_x_and_affixed_by_ars_y(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/vertical/x0_y1")
    subtree = add_vertical(ctx, member)
    assert crs.tick_until(subtree) == Status.SUCCESS
    assert [(r.ars, r.request, r.member_id) for r in rig.recorder.requests] == [
        ("ars_x", "add_member", "bay1/vertical/x0_y1"),
        ("ars_y", "affix_member", "bay1/vertical/x0_y1"),
    ]
    assert ctx.model.states[member.id] == RIVETED
    assert rig.vision.part_calls == [member.id]  # Inspection Check asked vision once
    assert rig.vision.part_cameras == ["zed_right"]  # through the camera ARS X presents it to
    # One vertical and its two rivets (one from each ARS's rivet dispenser) left the dispensers.
    assert ctx.model.remaining["vertical_dispenser_x"] == 4
    assert ctx.model.remaining["rivet_dispenser_x"] == 15 and ctx.model.remaining["rivet_dispenser_y"] == 15


def test_near_vertical_is_added_and_affixed_by_the_same_ars(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/vertical/x1_y1")
    assert crs.tick_until(add_vertical(ctx, member)) == Status.SUCCESS
    assert {(r.ars, r.request) for r in rig.recorder.requests} == {
        ("ars_y", "add_member"),
        ("ars_y", "affix_member"),
    }


def test_diagonal_is_placed_and_riveted_by_one_request(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/diagonal/face_x0")
    assert crs.tick_until(add_diagonal(ctx, member)) == Status.SUCCESS
    assert rig.recorder.members("add_member") == [member.id]
    assert ctx.model.states[member.id] == RIVETED


def test_cross_frame_then_active_grippers_engaged(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/cross_frame")
    assert crs.tick_until(add_cross_frame(ctx, member, Actuators(ctx))) == Status.SUCCESS
    assert rig.recorder.members("add_cross_frame") == [member.id]
    assert ctx.model.states[member.id] == PLACED
    assert rig.active.engaged == [True] * 4


def test_failed_parts_are_discarded_and_counted(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/diagonal/face_x0")
    rig.vision.part_verdicts[member.id] = [False]  # first part fails, the second passes
    assert crs.tick_until(add_diagonal(ctx, member)) == Status.SUCCESS
    assert rig.vision.part_calls == [member.id, member.id]
    assert ctx.model.remaining["diagonal_dispenser_x"] == 2  # two taken
    assert ctx.model.discarded["diagonal_dispenser_x"] == 1


def test_a_part_left_held_is_counted_against_the_dispenser_it_came_from(rig, crs, tmp_path):
    """ARS X still holds a cross frame from a request that failed (the operator then gave the cross
    frame to ARS Y through cross_frame_ars); it discards the frame before it fetches the diagonal
    asked for: the frames' dispenser counts it, the diagonals' only the diagonal placed."""
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/diagonal/face_x0")
    remaining = ctx.model.remaining
    frames, diagonals = remaining["cross_frame_dispenser"], remaining["diagonal_dispenser_x"]
    rig.ars["ars_x"].held_from = "cross_frame_dispenser"
    assert crs.tick_until(add_diagonal(ctx, member)) == Status.SUCCESS
    assert remaining["cross_frame_dispenser"] == frames - 1
    assert ctx.model.discarded["cross_frame_dispenser"] == 1
    assert remaining["diagonal_dispenser_x"] == diagonals - 1
    assert ctx.model.discarded["diagonal_dispenser_x"] == 0


def test_a_verdict_reaches_the_ars_that_gave_its_call_up_and_presented_the_part_again(rig, crs, tmp_path):
    """Vision takes longer than the ARS waits for an answer (as when a fault holds the CRS mid-
    inspection): the ARS presents the part again, and the verdict goes to that call, not the one
    given up. The ARS would otherwise present its part for ever."""
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/diagonal/face_x0")
    rig.vision.part_verdicts[member.id] = [False]  # the first part fails, its replacement passes
    rig.vision.part_delay_s = 1.5
    rig.ars["ars_x"].call_timeout_s = 0.5
    assert crs.tick_until(add_diagonal(ctx, member), timeout=60.0) == Status.SUCCESS
    assert rig.vision.part_calls == [member.id, member.id]  # each part judged once
    assert ctx.model.discarded["diagonal_dispenser_x"] == 1
    assert ctx.model.states[member.id] == RIVETED


def test_too_many_failed_parts_fail_the_request_and_cancel_the_ars_goal(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    ctx.board.set("inspection_attempts", 2)
    member = _member(ctx, "bay1/diagonal/face_x0")
    rig.vision.part_verdicts[member.id] = [False, False, False]
    rig.ars["ars_x"].max_parts = 5
    subtree = add_diagonal(ctx, member)
    assert crs.tick_until(subtree) == Status.FAILURE
    decorator = subtree.children[1].children[1]
    assert "2 part(s) failed inspection" in decorator.feedback_message
    assert ctx.model.states[member.id] == NOT_PLACED
    crs.wait_for(lambda: rig.recorder.requests[0].outcome in ("canceled", "failed"), what="ARS goal ended")


def test_a_part_vision_cannot_judge_is_kept_and_looked_at_again_not_discarded(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/diagonal/face_x0")
    undecided = rig.vision.CANNOT_JUDGE
    rig.vision.part_verdicts[member.id] = [undecided, undecided, True]
    assert crs.tick_until(add_diagonal(ctx, member), timeout=60.0) == Status.SUCCESS
    assert rig.vision.part_calls == [member.id] * 3  # one part, looked at three times
    assert ctx.model.discarded.get("diagonal_dispenser_x", 0) == 0
    assert ctx.model.states[member.id] == RIVETED


def test_a_part_vision_never_judges_becomes_a_fault_after_the_looks_allowed(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    ctx.board.set("inspection_looks", 2)
    member = _member(ctx, "bay1/diagonal/face_x0")
    rig.vision.part_verdicts[member.id] = [rig.vision.CANNOT_JUDGE] * 4
    subtree = add_diagonal(ctx, member)
    assert crs.tick_until(subtree, timeout=60.0) == Status.FAILURE
    decorator = subtree.children[1].children[1]
    assert "vision could not judge the part in 2 looks" in decorator.feedback_message
    assert ctx.model.discarded.get("diagonal_dispenser_x", 0) == 0
    assert ctx.model.states[member.id] == NOT_PLACED


def test_ars_failure_result_leaves_the_member_unplaced_with_the_reason(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/diagonal/face_y1")
    rig.ars["ars_y"].fail[member.id] = "rivet gun jammed"
    subtree = add_diagonal(ctx, member)
    assert crs.tick_until(subtree) == Status.FAILURE
    wait = subtree.children[1].children[-1]
    assert "rivet gun jammed" in wait.feedback_message and "ars_y" in wait.feedback_message
    assert ctx.model.states[member.id] == NOT_PLACED
    assert ctx.model.remaining["diagonal_dispenser_y"] == 4  # nothing placed, nothing discarded


def test_missing_ars_fails_with_the_reason_after_the_server_timeout(ros, crs, tmp_path):
    rig = crs.Rig(with_ars=False)
    try:
        ctx = crs.make_context(rig, crs.fast_config(tmp_path, ars_server_s=0.3))
        subtree = add_diagonal(ctx, _member(ctx, "bay1/diagonal/face_x0"))
        assert crs.tick_until(subtree, timeout=5.0) == Status.FAILURE
        send = subtree.children[1].children[0]
        # Usually "not available"; right after another test's ARS went away, discovery may still list
        # it for a moment, and then the goal is never acknowledged. Both name the missing ARS.
        message = send.feedback_message
        assert ("ARS 'ars_x' missing" in message and "/ars_x/add_member" in message) or (
            "ARS did not acknowledge" in message and "ars_x" in message
        ), message
    finally:
        rig.close()


def test_ars_gone_mid_request_fails_instead_of_waiting_forever(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path, ars_server_s=0.3))
    rig.ars["ars_x"].hold_s = 30.0
    subtree = add_diagonal(ctx, _member(ctx, "bay1/diagonal/face_x0"))
    crs.tick_until(subtree, until=lambda: len(rig.recorder.requests) == 1 and rig.vision.part_calls != [])
    for server in rig.ars["ars_x"].servers:
        server.destroy()
    assert crs.tick_until(subtree, timeout=10.0) == Status.FAILURE
    assert "gone while running" in subtree.children[1].children[-1].feedback_message


def _stop_ars_x(rig):
    for server in rig.ars["ars_x"].servers:
        server.destroy()


def _start_ars_x(rig, crs):
    """A new ARS X process's servers come up (a launcher restart)."""
    import rclpy

    node = rclpy.create_node("ars_x_restarted")
    rig.add(node)
    rig.ars["ars_x"] = crs.ArsStandIn(node, "ars_x", rig.recorder, rig.group)


def _replace_ars_x_mid_request(rig, crs, ctx, subtree, phase):
    """Kill ARS X's servers while it runs the subtree's request, at ``phase``, and bring up a new
    ARS X (a launcher restart); returns the new stand-in."""
    import rclpy
    from action_msgs.msg import GoalStatusArray

    rig.ars["ars_x"].hold_s = 30.0
    # An earlier ARS X that died is still listed for its lease, as DDS keeps a lost participant's
    # endpoints: its server's status publisher.
    lingering = rclpy.create_node("ars_x_lingering")
    rig.add(lingering)
    lingering.create_publisher(GoalStatusArray, "/ars_x/add_member/_action/status", 1)
    crs.wait_for(
        lambda: (
            "ars_x_lingering"
            in {
                i.node_name for i in ctx.node.get_publishers_info_by_topic("/ars_x/add_member/_action/status")
            }
        )
    )
    if phase == "waiting for the part":
        # The CRS learns the goal was accepted only after the ARS that took it died: its request
        # for the result reaches no server, and the server it finds next is the restarted one.
        rig.ars["ars_x"].present_after_s = 30.0
        send = next(b for b in subtree.iterate() if isinstance(b, SendArsRequest))
        crs.tick_until(subtree, until=lambda: send.req.send_future is not None)
        crs.wait_for(lambda: len(rig.recorder.requests) == 1, what="the ARS runs the goal")
        crs.wait_for(send.req.send_future.done, what="the acceptance reaches the CRS")
        _stop_ars_x(rig)
        crs.tick_until(subtree, until=lambda: send.status == Status.SUCCESS)
    else:
        crs.tick_until(subtree, until=lambda: len(rig.recorder.requests) == 1 and rig.vision.part_calls != [])
        _stop_ars_x(rig)
    _start_ars_x(rig, crs)
    return rig.ars["ars_x"]


@pytest.mark.parametrize("phase", ["waiting for the result", "waiting for the part"])
def test_ars_replaced_mid_request_is_sent_the_request_again(rig, crs, tmp_path, phase):
    """A restarted ARS knows from its state file what the request did; the CRS sends it again to the
    new server (no fault), and the member is placed once."""
    ctx = crs.make_context(rig, crs.fast_config(tmp_path, ars_server_s=0.3))
    events = []
    ctx.event_listeners.append(lambda severity, code, text: events.append((code, text)))
    member = _member(ctx, "bay1/diagonal/face_x0")
    subtree = add_diagonal(ctx, member)
    _replace_ars_x_mid_request(rig, crs, ctx, subtree, phase)
    assert crs.tick_until(subtree, timeout=10.0) == Status.SUCCESS
    requests = [(r.ars, r.request, r.member_id) for r in rig.recorder.requests]
    assert requests == [("ars_x", "add_member", member.id)] * 2  # once to each ARS X process
    assert rig.recorder.requests[1].outcome == "succeeded"
    assert ctx.model.states[member.id] == RIVETED
    assert ctx.model.remaining["diagonal_dispenser_x"] == 3  # one part taken: nothing placed twice
    resent = [text for code, text in events if code == "ARS_REQUEST_RESENT"]
    assert len(resent) == 1 and member.id in resent[0] and "(1 of 2)" in resent[0], events


def test_a_resent_request_the_restarted_ars_finishes_without_a_part_succeeds(rig, crs, tmp_path):
    """The restarted ARS had set the member before it was killed (its state file says so): sent
    again, it finishes the request without presenting a part, and that is the member done."""
    ctx = crs.make_context(rig, crs.fast_config(tmp_path, ars_server_s=0.3))
    member = _member(ctx, "bay1/diagonal/face_x0")
    subtree = add_diagonal(ctx, member)
    rig.ars["ars_x"].hold_s = 30.0
    crs.tick_until(subtree, until=lambda: len(rig.recorder.requests) == 1 and rig.vision.part_calls != [])
    _stop_ars_x(rig)
    import rclpy

    node = rclpy.create_node("ars_x_restarted")
    rig.add(node)
    restarted = crs.ArsStandIn(node, "ars_x", rig.recorder, rig.group)
    restarted.present_parts = False  # it lets go and retreats: no part to present
    rig.ars["ars_x"] = restarted
    assert crs.tick_until(subtree, timeout=10.0) == Status.SUCCESS
    assert [r.outcome for r in rig.recorder.requests][1:] == ["succeeded"]
    assert rig.vision.part_calls == [member.id]  # the part was inspected once, by the first ARS X
    assert ctx.model.states[member.id] == RIVETED


@pytest.mark.parametrize("phase", ["waiting for the result", "waiting for the part"])
def test_ars_replaced_mid_request_once_too_often_fails_with_the_reason(rig, crs, tmp_path, phase):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path, ars_server_s=0.3))
    ctx.board.set("ars_resends", 0)
    subtree = add_diagonal(ctx, _member(ctx, "bay1/diagonal/face_x0"))
    _replace_ars_x_mid_request(rig, crs, ctx, subtree, phase)
    assert crs.tick_until(subtree, timeout=10.0) == Status.FAILURE
    assert rig.recorder.requests[1:] == []  # nothing sent to the new server
    failed = [b for b in subtree.iterate() if b.status == Status.FAILURE and b.children == []]
    message = failed[0].feedback_message
    # Found gone by the graph, or told by the new server that answered the result request.
    assert "does not know the goal" in message and "ars_x" in message, message
    waiting = "Wait For Part" if phase == "waiting for the part" else "Wait For AddMember"
    assert failed[0].name.startswith(waiting), failed[0].name


def test_member_the_model_says_placed_is_never_requested(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    member = _member(ctx, "bay1/vertical/x0_y1")
    ctx.model.place(member.id)
    assert crs.tick_until(add_vertical(ctx, member)) == Status.SUCCESS
    assert [r.request for r in rig.recorder.requests] == ["affix_member"]


def test_build_bay_in_figure_order(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    assert crs.tick_until(build_bay(ctx, 1, Actuators(ctx)), timeout=20.0) == Status.SUCCESS
    order = [(r.request, r.member_id) for r in rig.recorder.requests]
    assert order == [
        ("add_cross_frame", "bay1/cross_frame"),
        ("add_member", "bay1/vertical/x0_y1"),
        ("affix_member", "bay1/vertical/x0_y1"),
        ("add_member", "bay1/vertical/x1_y0"),
        ("affix_member", "bay1/vertical/x1_y0"),
        ("add_member", "bay1/vertical/x0_y0"),
        ("affix_member", "bay1/vertical/x0_y0"),
        ("add_member", "bay1/vertical/x1_y1"),
        ("affix_member", "bay1/vertical/x1_y1"),
        ("add_member", "bay1/diagonal/face_x0"),
        ("add_member", "bay1/diagonal/face_y0"),
        ("add_member", "bay1/diagonal/face_x1"),
        ("add_member", "bay1/diagonal/face_y1"),
    ]


def test_test_bay_compresses_inspects_and_marks_the_bay_inspected(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    for m in ctx.mission.bay_members(1):
        ctx.model.override(m.id, PLACED if m.kind == "cross_frame" else RIVETED)
    assert crs.tick_until(bay_test(ctx, 1, Actuators(ctx))) == Status.SUCCESS
    assert rig.top.engaged == [True] * 4 and rig.active.engaged == [True] * 4
    assert rig.vision.bay_calls == [1]
    assert [g for g in rig.cameras.trajectories.goals] == [[1.15, 1.15], [0.0, 0.0]]
    # The ZEDs looked once the mounts stood still inward, not when their trajectory ended (the
    # stand-in's servos trail it by 0.3 s).
    ((at, speed),) = rig.vision.mounts_at_bay_calls
    assert at == pytest.approx([1.15, 1.15], abs=0.005) and speed == [0.0, 0.0], (at, speed)
    # 50 N / 50000 N/m = 1 mm above the lowered position.
    assert all(abs(p - 0.101) < 1e-9 for p in rig.lifter.positions)
    assert all(ctx.model.states[m.id] == INSPECTED for m in ctx.mission.bay_members(1))


def test_failed_bay_inspection_fails_test_bay_with_vision_reasons(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    rig.vision.bay_passes = False
    subtree = bay_test(ctx, 1, Actuators(ctx))
    assert crs.tick_until(subtree) == Status.FAILURE
    from tlt_crs.behaviours.faults import failure_reason

    assert "corner x0_y0 misaligned" in failure_reason(subtree)


def test_foundation_rivets(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    assert crs.tick_until(add_foundation_rivets(ctx)) == Status.SUCCESS
    assert {(r.ars, r.member_id) for r in rig.recorder.requests} == {
        ("ars_x", "foundation/x0_y0"),
        ("ars_x", "foundation/x0_y1"),
        ("ars_y", "foundation/x1_y0"),
        ("ars_y", "foundation/x1_y1"),
    }
    assert all(ctx.model.states[f"foundation/{c}"] == RIVETED for c in ("x0_y0", "x0_y1", "x1_y0", "x1_y1"))


def test_ars_giving_up_on_parts_is_recorded_with_its_reason(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    ctx.board.set("inspection_attempts", 5)
    member = _member(ctx, "bay1/diagonal/face_x0")
    rig.vision.part_verdicts[member.id] = [False] * 5
    rig.ars["ars_x"].max_parts = 2  # the ARS gives up before the CRS would
    subtree = add_diagonal(ctx, member)
    assert crs.tick_until(subtree) == Status.FAILURE
    from tlt_crs.behaviours.faults import failure_reason

    assert "no part passed inspection (2 discarded)" in failure_reason(subtree)
    assert ctx.model.discarded["diagonal_dispenser_x"] == 2
    assert ctx.model.remaining["diagonal_dispenser_x"] == 2
    assert ctx.model.states[member.id] == NOT_PLACED


# A vision process's /vision/inspect_bay: it says its readiness as vision does (a reason while it
# cannot place its cameras, then ready), and either never answers (it is about to be killed) or
# passes the bay. It prints each request it takes.
VISION_PROCESS = """
import sys, threading, time
import rclpy
from rclpy.executors import MultiThreadedExecutor
from tlt_interfaces.srv import InspectBay
from tlt_common import ros_names
from tlt_common.ros.readiness import ReadinessPublisher

mode = sys.argv[1]
rclpy.init()
node = rclpy.create_node("vision")
readiness = ReadinessPublisher(node, ros_names.VISION_STATUS, "vision")
readiness.say("no joint state for camera_mount_1 yet")

def inspect(request, response):
    print("request", request.bay, flush=True)
    if mode == "forget":
        threading.Event().wait()
    response.report.target_id = f"bay{request.bay}"
    response.report.passed = True
    return response

node.create_service(InspectBay, ros_names.VISION_INSPECT_BAY, inspect)
time.sleep(0.3)
readiness.say("")
print("ready", flush=True)
executor = MultiThreadedExecutor()
executor.add_node(node)
executor.spin()
"""


class _VisionProcess:
    def __init__(self, mode: str) -> None:
        import os
        import subprocess
        import sys
        import threading

        self.lines: list[str] = []
        self.process = subprocess.Popen(
            [sys.executable, "-c", VISION_PROCESS, mode],
            stdout=subprocess.PIPE,
            text=True,
            env=os.environ.copy(),
        )
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self.lines.append(line.strip())

    def kill(self) -> None:
        import signal

        if self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=10.0)


def test_a_bay_inspection_lost_with_a_killed_vision_is_sent_again_to_the_restarted_one(rig, crs, tmp_path):
    """Vision killed (SIGKILL) with Inspect Bay out and restarted by the launcher: the CRS sends the
    inspection again once the new vision says ready, and Test Bay passes without a fault."""
    rig.vision.withdraw()  # vision is a process of its own here
    visions = [_VisionProcess("forget")]
    try:
        ctx = crs.make_context(rig, crs.fast_config(tmp_path))
        for m in ctx.mission.bay_members(1):
            ctx.model.override(m.id, PLACED if m.kind == "cross_frame" else RIVETED)
        crs.wait_for(lambda: "ready" in visions[0].lines, timeout=30.0, what="the first vision")
        crs.wait_for(lambda: ctx.vision_status.not_ready() == "", timeout=10.0, what="vision's ready word")
        subtree = bay_test(ctx, 1, Actuators(ctx))
        crs.tick_until(subtree, until=lambda: "request 1" in visions[0].lines, timeout=30.0)
        visions[0].kill()
        visions.append(_VisionProcess("answer"))
        assert crs.tick_until(subtree, timeout=60.0) == Status.SUCCESS
        assert visions[1].lines.count("request 1") == 1
        assert all(ctx.model.states[m.id] == INSPECTED for m in ctx.mission.bay_members(1))
    finally:
        for vision in visions:
            vision.kill()
