"""The ARS process without hardware: start-up checks, Start/Pause/Resume/Stop bookkeeping and
refusals that happen before anything moves."""

from __future__ import annotations

import contextlib
import signal
import threading
import time

import numpy as np
import pytest
import rclpy
import yaml
from action_msgs.msg import GoalStatus
from py_trees.common import Status
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from tlt_interfaces.action import AddMember, AffixMember
from tlt_interfaces.msg import MemberState, MissionProgress
from tlt_interfaces.srv import GroundCommand, SetBlackboardValue

from tlt_ars.command_line import build_parser, config_from_args
from tlt_ars.config import ars_config_from_dict, default_config_path
from tlt_ars.mission_state import Request
from tlt_ars.node import ArsNode, main
from tlt_ars.planning.reachability import UnreachableMember
from tlt_ars.planning.targets import Target
from tlt_ars.request_data import RequestData, RequestFile, RequestFileError
from tlt_common import ros_names
from tlt_common.bt.writable_blackboard import value_msg
from tlt_common.config_schema import load_yaml
from tlt_common.mission.schema import load_mission
from tlt_common.ros.action_client import SerialisedActionClient
from tlt_common.ros.action_graph import describe_action_server_graph
from tlt_common.ros.node_teardown import destroy_node

pytestmark = pytest.mark.timeout(60)


def test_main_refuses_a_bad_config_with_file_key_and_reason(tmp_path, capsys):
    raw = load_yaml(default_config_path("ars_x"))
    raw["arm"]["velocity_scale"] = 3.0
    bad = tmp_path / "ars_x.yaml"
    bad.write_text(yaml.safe_dump(raw))
    assert main(["--ars", "ars_x", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "arm.velocity_scale" in err
    assert main(["--ars", "ars_y", "--config", str(default_config_path("ars_x"))]) == 2
    assert "file is for 'ars_x', not 'ars_y'" in capsys.readouterr().err


def test_the_command_line_sets_the_arm_speed_and_a_bad_one_is_refused_naming_the_option(capsys):
    def speed(*extra: str) -> float:
        args = build_parser().parse_args(["--ars", "ars_y", *extra])
        return config_from_args(args).arm["velocity_scale"]

    shipped = load_yaml(default_config_path("ars_y"))["arm"]["velocity_scale"]
    assert speed() == speed("--velocity-scale", "") == shipped
    assert speed("--velocity-scale", "0.8") == 0.8 != shipped
    assert main(["--ars", "ars_y", "--velocity-scale", "3"]) == 2
    err = capsys.readouterr().err
    assert "ars_y.yaml with --velocity-scale 3: arm.velocity_scale" in err


def test_a_member_out_of_reach_stops_the_start(tmp_path):
    scene = load_yaml("config/planning/scene.yaml")
    scene["arms"]["ars_x"]["base"] = [-3.0, -3.0, 0.0]  # the arm moved far from the tower
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    raw = load_yaml(default_config_path("ars_x"))
    raw["scene"] = str(path)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(UnreachableMember, match="bay1/cross_frame: ars_x cannot place"):
            ArsNode(ars_config_from_dict(raw), context=context)
    finally:
        rclpy.try_shutdown(context=context)


# How long a probe waits to discover the ARS's servers: once, in a clean-clone run on a loaded
# machine, a new ARS's action server was still undiscovered after 10 s.
DISCOVERY_S = 30.0


@contextlib.contextmanager
def _spun_ars(raw: dict):
    """An ARS from the ARS file ``raw`` and a probe node, spun together in a context of their own."""
    context = rclpy.Context()
    rclpy.init(context=context)
    ars = ArsNode(ars_config_from_dict(raw), context=context)
    client = Node("ars_probe", context=context)
    executor = MultiThreadedExecutor(num_threads=4, context=context)
    executor.add_node(ars)
    executor.add_node(client)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        yield ars, client
    finally:
        executor.shutdown(timeout_sec=5)
        thread.join(timeout=5)
        ars.close()
        destroy_node(ars)
        destroy_node(client)
        rclpy.try_shutdown(context=context)


@pytest.fixture
def idle_ars():
    raw = load_yaml(default_config_path("ars_x"))
    raw.update(started_on_launch=False, check_reach=False)
    raw["timeouts"]["planning_s"] = 3.0  # no arm here: a request that gets to planning fails soon
    with _spun_ars(raw) as spun:
        yield spun


def _discovered(client: Node, action_type: type, kind: str) -> SerialisedActionClient:
    """A client of ARS X's action ``kind`` on node ``client``, once it has found the server."""
    name = ros_names.ars_action("ars_x", kind)
    action = SerialisedActionClient(client, action_type, name)
    assert action.wait_for_server(timeout_sec=DISCOVERY_S), describe_action_server_graph(client, name)
    return action


def _wait(future, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not future.done():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)
    return future.result()


def test_requests_wait_for_start_and_ground_commands_follow_their_rules(idle_ars):
    ars, client = idle_ars
    action = _discovered(client, AddMember, "add_member")
    ground = client.create_client(GroundCommand, ros_names.ground_command_service("ars_x"))
    assert ground.wait_for_service(timeout_sec=DISCOVERY_S)

    def request(member_id="bay1/vertical/x0_y0"):
        goal = AddMember.Goal(kind=1, bay=1, member_id=member_id, position="x0_y0", ars="ars_x")
        handle = _wait(action.send_goal_async(goal))
        assert handle.accepted  # acknowledged, then checked
        return _wait(handle.get_result_async())

    def command(code):
        return _wait(ground.call_async(GroundCommand.Request(command=code)))

    refused = request()
    assert refused.status == GoalStatus.STATUS_ABORTED
    assert refused.result.reason == "rejected: ars_x is not started (waiting for the ground's Start)"
    assert not command(GroundCommand.Request.RESUME).accepted  # not paused
    start = command(GroundCommand.Request.START)
    assert start.accepted and ars.started
    assert command(GroundCommand.Request.START).reason == "already started"
    assert "unknown member" in request("bay1/vertical/nowhere").result.reason
    assert command(GroundCommand.Request.PAUSE).accepted
    assert not command(GroundCommand.Request.PAUSE).accepted
    assert not command(GroundCommand.Request.START).accepted  # paused: Resume continues
    assert request().result.reason == "rejected: ars_x is paused"
    assert command(GroundCommand.Request.RESUME).accepted
    assert not command(9).accepted
    assert command(GroundCommand.Request.STOP).accepted
    deadline = time.monotonic() + 10
    while not ars.finished.is_set():  # no arm state: it waits timeouts.stop_s, then stops anyway
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert request().result.reason == "rejected: stopped by ground command"


def test_the_ars_applies_the_grounds_writes_to_its_keys_and_says_why_it_refuses_one(idle_ars):
    ars, client = idle_ars
    writes = client.create_client(SetBlackboardValue, ros_names.set_blackboard_service("ars_x"))
    assert writes.wait_for_service(timeout_sec=DISCOVERY_S)

    def write(key, value):
        return _wait(writes.call_async(SetBlackboardValue.Request(key=key, value=value_msg(value))))

    ok = write("present_part_timeout_s", 120.0)
    assert ok.accepted and ars.config.timeouts["present_part_s"] == 120.0
    assert ars.ctx.config.timeouts["present_part_s"] == 120.0  # what the behaviours read
    refused = write("present_part_timeout_s", 1.0)
    assert not refused.accepted and "below the minimum 10" in refused.reason
    unknown = write("velocity_scale", 0.9)
    assert not unknown.accepted and unknown.reason == "unknown key 'velocity_scale'"
    assert ars.config.timeouts["present_part_s"] == 120.0


@pytest.mark.parametrize("stop", ["ground", signal.SIGINT, signal.SIGTERM])
def test_process_exits_cleanly_on_ground_stop_and_on_a_signal(stop, wait_for_service):
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "tlt_ars.node", "--ars", "ars_y", "--no-reach-check"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        ground = wait_for_service(proc, GroundCommand, ros_names.ground_command_service("ars_y"), 30)
        if stop == "ground":
            future = ground.call_async(GroundCommand.Request(command=GroundCommand.Request.STOP))
            wait_for_service.executor.spin_until_future_complete(future, timeout_sec=10)
            assert future.result().accepted
        else:  # as a launcher stops it: rclpy's context stays valid until the node is destroyed
            proc.send_signal(stop)
        assert proc.wait(timeout=20) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_request_is_judged_on_mission_progress_newer_than_it(idle_ars):
    """The CRS sends AffixMember right after the placement; the MissionProgress saying so may
    arrive just after the goal: the ARS judges the goal on that newer message, not the old one."""
    ars, client = idle_ars
    ars.started = True
    action = _discovered(client, AffixMember, "affix_member")
    progress = client.create_publisher(MissionProgress, ros_names.CRS_MISSION_PROGRESS, 10)
    member = "bay1/vertical/x0_y0"
    goal = AffixMember.Goal(kind=1, member_id=member, bay=1, position="x0_y0", ars="ars_x")

    stale = _wait(_wait(action.send_goal_async(goal)).get_result_async())  # no news: not placed
    assert stale.result.reason == f"rejected: member '{member}' is not placed yet: nothing to affix"

    handle = _wait(action.send_goal_async(goal))
    time.sleep(0.3)
    placed = MissionProgress(mission=ars.ctx.state.mission.name, current_bay=1, started=True)
    placed.members = [
        MemberState(member_id=member, kind=MemberState.KIND_VERTICAL, bay=1, state=MemberState.STATE_PLACED)
    ]
    progress.publish(placed)
    result = _wait(handle.get_result_async(), timeout=60.0)
    assert "not placed" not in result.result.reason  # taken: it went on to the tree (no arm here)


def test_a_goal_for_the_running_request_takes_the_job_over(idle_ars):
    """A restarted CRS sends the request its predecessor had in flight again: the new goal follows
    the running job (the member is placed once) and the old one ends as superseded; any other
    request is still refused as busy."""
    ars, client = idle_ars
    ars.started = True
    action = _discovered(client, AddMember, "add_member")
    goal = AddMember.Goal(kind=1, bay=1, member_id="bay1/vertical/x0_y0", position="x0_y0", ars="ars_x")
    first = _wait(action.send_goal_async(goal))
    deadline = time.monotonic() + 10
    while ars.active is None or ars.active.handle.goal_id != first.goal_id:
        assert time.monotonic() < deadline, "the first goal never ran"
        time.sleep(0.02)
    job = ars.tree.job
    second = _wait(action.send_goal_async(goal))
    superseded = _wait(first.get_result_async())
    assert superseded.status == GoalStatus.STATUS_ABORTED
    assert superseded.result.reason.startswith("superseded"), superseded.result.reason
    assert ars.active.handle.goal_id == second.goal_id and ars.tree.job is job  # the same job, not a new one

    other = AddMember.Goal(kind=1, bay=1, member_id="bay1/vertical/x1_y0", position="x1_y0", ars="ars_x")
    busy = _wait(_wait(action.send_goal_async(other)).get_result_async())
    assert busy.result.reason == "rejected: busy: ars_x is running add_member for 'bay1/vertical/x0_y0'"
    # No arm here: the job fails in the end, and its outcome reaches the goal that took it over.
    result = _wait(second.get_result_async(), timeout=60.0)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert "no fresh joint state on '/ur_x/joint_states'" in result.result.reason, result.result.reason
    assert ars.active is None


def test_a_request_starts_on_a_tick_when_its_goal_is_accepted_not_at_the_next_period():
    """The CRS waits for a request's first feedback: the ARS ticks the request's branch as it
    accepts the goal, so the feedback does not wait for the tick timer (1 s apart here)."""
    raw = load_yaml(default_config_path("ars_x"))
    raw.update(started_on_launch=True, check_reach=False, tick_rate_hz=1.0)
    raw["timeouts"].update(server_s=0.2, service_s=0.2, stop_s=0.2, sensor_s=0.2, planning_s=0.2)
    with _spun_ars(raw) as (_ars, client):
        action = _discovered(client, AddMember, "add_member")
        goal = AddMember.Goal(kind=1, bay=1, member_id="bay1/vertical/x0_y0", position="x0_y0", ars="ars_x")
        delays = []
        for _ in range(3):  # were it the timer's tick, each delay would be anywhere up to 1 s
            first = threading.Event()
            sent = time.monotonic()
            handle = _wait(action.send_goal_async(goal, feedback_callback=lambda _f, e=first: e.set()))
            assert handle.accepted and first.wait(5.0), "no feedback"
            delays.append(time.monotonic() - sent)
            result = _wait(handle.get_result_async())  # no arm here: it fails on a later tick
            assert result.status == GoalStatus.STATUS_ABORTED
        assert max(delays) < 0.4, delays


def test_a_request_s_later_phases_are_built_on_the_tick_after_the_one_that_starts_it():
    """The CRS waits for a request's first tick: on it only the first phase of an Add Member is
    built; the rest are built on the next tick, the same branch as one built whole."""
    from tlt_ars.goals import request_of
    from tlt_ars.tree import Job, progress
    from tlt_common.bt.status_codec import TreeShape

    raw = load_yaml(default_config_path("ars_x"))
    raw.update(started_on_launch=True, check_reach=False)
    context = rclpy.Context()
    rclpy.init(context=context)
    ars = ArsNode(ars_config_from_dict(raw), context=context)  # not spun: the test ticks the tree
    try:
        changes: list[int] = []
        ars.tree.on_change.append(lambda: changes.append(1))
        goal = AddMember.Goal(kind=1, bay=1, member_id="bay1/vertical/x0_y0", position="x0_y0", ars="ars_x")
        ars.tree.submit(Job(request_of("add_member", goal), lambda ok, why: None))
        ars.tree.tick()
        branch = ars.tree.branch
        assert [c.name for c in branch.children] == [
            "Load Rivet",
            "Get Inspected Member",
            "Place Member",
            "Rivet Member",
        ]
        assert branch.children[0].status == Status.RUNNING
        assert not branch.children[2].children and not branch.children[3].children
        assert progress(branch) == 0.0  # not a fraction of a whole not known yet
        assert changes == [1]
        ars.tree.tick()
        whole = ars.tree.builder.branch("add_member", ars.ctx.data.member)
        assert [n.path for n in TreeShape.of(branch).nodes] == [n.path for n in TreeShape.of(whole).nodes]
        assert len(TreeShape.of(branch).nodes) > 100 and changes == [1, 1]
    finally:
        ars.close()
        destroy_node(ars)
        rclpy.try_shutdown(context=context)


def _kept_diagonal(path, holding: str | None) -> None:
    """A state file that says the ARS riveted diagonal face_y0 of the shipped mission, with the
    diagonal still ``holding`` or let go of, and went down before the CRS heard of it."""
    mission = load_mission("missions/one_bay.yaml")
    member = mission.member("bay1/diagonal/face_y0")
    pre = np.eye(4)
    pre[:3, 3] = (0.5, 0.5, 1.0)
    RequestFile(path, mission, "ars_x").save(RequestData(
        request=Request("add_member", member.id, "ars_x", bay=1, kind=2, position="face_y0"),
        member=member, holding=holding, targets={"place": Target("test", pre, pre)}, recorded="placed",
    ))  # fmt: skip


def test_a_state_file_that_cannot_be_read_stops_the_start(tmp_path):
    path = tmp_path / "ars_x.json"
    path.write_text("{ half a file")
    raw = load_yaml(default_config_path("ars_x"))
    raw.update(check_reach=False, state_file=str(path))
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(RequestFileError, match=f"{path}: ARS state file is not valid JSON"):
            ArsNode(ars_config_from_dict(raw), context=context)
        probe = Node("ars_probe", context=context)
        assert "ars_x" not in probe.get_node_names()  # nothing of it left for later nodes to find
        destroy_node(probe)
    finally:
        rclpy.try_shutdown(context=context)


def test_a_restarted_ars_finishes_the_request_its_state_file_kept_and_drops_it_for_another(tmp_path):
    """The CRS never heard how the kept request ended and sends it again: the restarted ARS runs
    its Finish (let go, retreat), not the whole request, nor refuses it as placed. While the
    riveted member is in the gripper nothing else runs; once it was let go of, another request
    drops the file. No arm here: each request fails at its first motion."""
    path = tmp_path / "ars_x.json"
    raw = load_yaml(default_config_path("ars_x"))
    raw.update(check_reach=False, state_file=str(path))
    raw["timeouts"].update(server_s=0.5, planning_s=0.5)
    kept = AddMember.Goal(kind=2, bay=1, member_id="bay1/diagonal/face_y0", position="face_y0", ars="ars_x")
    other = AddMember.Goal(kind=1, bay=1, member_id="bay1/vertical/x0_y0", position="x0_y0", ars="ars_x")

    def outcome(action, goal) -> str:
        return _wait(_wait(action.send_goal_async(goal)).get_result_async(), timeout=30.0).result.reason

    _kept_diagonal(path, holding="diagonal")
    with _spun_ars(raw) as (ars, client):
        assert ars.ctx.state.is_placed("bay1/diagonal/face_y0")
        action = _discovered(client, AddMember, "add_member")
        assert outcome(action, kept).startswith("Finish Add Member/Release/Open Grasp")
        assert path.exists()  # still kept: it failed
        assert outcome(action, other) == (
            "rejected: the gripper still holds 'bay1/diagonal/face_y0', placed in the tower:"
            " only add_member for it, sent again, lets go of it"
        )

    _kept_diagonal(path, holding=None)  # let go of; the Retreat failed
    with _spun_ars(raw) as (ars, client):
        action = _discovered(client, AddMember, "add_member")
        assert outcome(action, other).startswith("Add Member/Load Rivet/")
        assert not path.exists()
        assert outcome(action, kept) == "rejected: member 'bay1/diagonal/face_y0' is already placed"


def test_the_tree_ticks_on_while_ros_time_stands_still(idle_ars, stop_ros_time):
    # On hardware ROS time is the system clock; set back, it stands still for a timer on it, which
    # stopped the ARS's tree for as long as the step.
    ars, _ = idle_ars
    ticks = ars.tree.tree.count
    stop_ros_time(ars)
    deadline = time.monotonic() + 10.0
    while ars.tree.tree.count < ticks + 5:
        assert time.monotonic() < deadline, "no ticks while ROS time stands still"
        time.sleep(0.02)
