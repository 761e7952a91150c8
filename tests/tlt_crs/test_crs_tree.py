"""The whole CRS tree (Fig. 13) in a CRS node, against stand-in ARSs, vision and driver topics:
a one-bay build, pause and resume mid-subtree, faults and help, Stop, and every refusal."""

from __future__ import annotations

import time

import pytest
from py_trees.common import Status

from tlt_common import ros_names
from tlt_common.ccsds.reasons import AckStage
from tlt_crs.context import RunState
from tlt_crs.index_record import IndexRecord
from tlt_crs.node import build_node


class Acks:
    def __init__(self) -> None:
        self.stages: list[tuple[AckStage, str]] = []

    def __call__(self, stage: AckStage, reason: str) -> None:
        self.stages.append((stage, reason))

    @property
    def final(self) -> tuple[AckStage, str] | None:
        return self.stages[-1] if len(self.stages) > 1 or self.rejected else None

    @property
    def rejected(self) -> bool:
        return bool(self.stages) and self.stages[0][0] == AckStage.REJECTED


@pytest.fixture
def crs_node(rig, crs, tmp_path):
    node = build_node(crs.fast_config(tmp_path))
    rig.add(node)
    crs.wait_for(lambda: not node.ctx.not_ready(), what="driver states")
    # The tree's first tick initialises the blackboard: a test that reads it before (a clean-clone
    # run on a loaded machine did) reads every key unset.
    crs.wait_for(
        lambda: node.ctx.board.get("tower_built") is not None, timeout=10.0, what="the blackboard initialised"
    )
    yield node
    node.interrupt()
    node.destroy_node()


def _submit(node, crs, name, params=None, wait=True):
    acks = Acks()
    node.commands.submit(name, params, acks)
    if wait and not acks.rejected:
        crs.wait_for(lambda: acks.final is not None, what=f"{name} completion")
    return acks


def _start(node, crs) -> Acks:
    """Start, again while refused as not ready: on a loaded machine a stand-in's state can arrive
    late enough to count as silent for a moment (the refusal itself is tested below)."""
    deadline = time.monotonic() + 10.0
    while True:
        acks = _submit(node, crs, "start")
        if not (acks.rejected and acks.stages[0][1].startswith("not ready")):
            assert not acks.rejected, acks.stages
            return acks
        assert time.monotonic() < deadline, acks.stages
        time.sleep(0.2)


def test_one_bay_mission_is_built_in_order_and_ends_idle(rig, crs, crs_node):
    assert crs_node.ctx.run_state == RunState.IDLE
    time.sleep(0.2)
    assert rig.recorder.requests == []  # started is false at start-up: nothing moves
    acks = _start(crs_node, crs)
    assert [s for s, _ in acks.stages] == [AckStage.ACCEPTED, AckStage.COMPLETED]
    crs.wait_for(lambda: crs_node.ctx.model.tower_built, timeout=30.0, what="tower built")
    members = rig.recorder.members()
    assert len(members) == 4 + 4 + 4 + 1 + 4  # adds, affixes, diagonals, cross frame, foundation rivets
    assert rig.recorder.members("add_member") == sorted(
        set(rig.recorder.members("add_member")), key=members.index
    )
    assert all(r.outcome == "succeeded" for r in rig.recorder.requests)
    assert all(c == 0 for a in rig.ars.values() for c in a.commands)  # START forwarded to each ARS
    assert set(rig.ars) == {"ars_x", "ars_y"} and all(a.commands for a in rig.ars.values())
    crs.wait_for(lambda: crs_node.root.status == Status.SUCCESS, what="idle")
    assert crs_node.ctx.run_state == RunState.DONE and crs_node.ctx.board.get("tower_built") is True
    progress = crs_node.progress()
    assert progress.tower_built and progress.bays_built == 1 and progress.run_state == RunState.DONE
    assert IndexRecord(crs_node.ctx.mission, crs_node.ctx.config.progress_file).indexed(1)


def test_start_is_refused_while_a_driver_is_silent_and_taken_once_it_reports(rig, crs, crs_node):
    rig.lifter.publishing = False
    crs.wait_for(lambda: "lifter" in crs_node.ctx.hardware_not_ready(), what="lifter state gone stale")
    refused = _submit(crs_node, crs, "start")
    assert refused.rejected and refused.stages[0][1].startswith("not ready: lifter: state ")
    assert not crs_node.ctx.started and rig.recorder.requests == []
    rig.lifter.publishing = True
    crs.wait_for(lambda: not crs_node.ctx.not_ready(), what="lifter state back")
    final = _submit(crs_node, crs, "start").final
    assert final[0] == AckStage.COMPLETED, final[1]


def test_start_is_refused_until_each_ars_has_a_calibrated_end_effector_and_an_active_arm(rig, crs, crs_node):
    """An ARS's end effector refuses every motion until its width joint is zeroed on the limit
    switch, and an arm in protective stop moves nothing: the operator is told at Start, not by a
    request failing mid-bay."""
    from tlt_interfaces.msg import HardwareStatus

    rig.ars["ars_y"].ee_calibrated = False
    crs.wait_for(lambda: "ee_y" in crs_node.ctx.not_ready(), what="ee_y reported uncalibrated")
    refused = _submit(crs_node, crs, "start")
    assert refused.rejected and "ee_y: width joint not calibrated yet" in refused.stages[0][1]
    rig.ars["ars_y"].ee_calibrated = True
    crs.wait_for(lambda: not crs_node.ctx.not_ready(), what="ee_y calibrated")

    status = rig.node.create_publisher(HardwareStatus, ros_names.hardware_status_topic("ur_x"), 10)

    def arm(lifecycle: int, fault: str) -> None:
        status.publish(HardwareStatus(component="ur_x", lifecycle_state=lifecycle, fault=fault))

    crs.wait_for(
        lambda: arm(HardwareStatus.LIFECYCLE_ERROR, "protective stop") or "ur_x" in crs_node.ctx.not_ready(),
        what="ur_x reported in error",
    )
    refused = _submit(crs_node, crs, "start")
    assert refused.rejected and "ur_x: arm not active (protective stop)" in refused.stages[0][1]
    assert not crs_node.ctx.started and rig.recorder.requests == []
    crs.wait_for(
        lambda: arm(HardwareStatus.LIFECYCLE_ACTIVE, "") or not crs_node.ctx.not_ready(), what="ur_x active"
    )
    assert _start(crs_node, crs).final[0] == AckStage.COMPLETED


def test_pause_holds_the_build_and_resume_continues_where_it_paused(rig, crs, crs_node):
    rig.ars["ars_x"].hold_s = 0.3
    rig.lifter.trajectories.time_scale = 0.02  # 75 s raise at 1 cm/s -> 1.5 s
    _start(crs_node, crs)
    crs.wait_for(lambda: rig.lifter.trajectories.goals != [], what="raise started")
    acks = _submit(crs_node, crs, "pause")
    assert acks.final[0] == AckStage.COMPLETED
    assert crs_node.ctx.run_state == RunState.PAUSED
    crs.wait_for(lambda: rig.lifter.trajectories.canceled == 1, what="lifter motion held")
    assert all(2 in a.commands for a in rig.ars.values())  # PAUSE forwarded
    goals_when_paused = len(rig.lifter.trajectories.goals)
    time.sleep(0.5)
    assert len(rig.lifter.trajectories.goals) == goals_when_paused and rig.recorder.requests == []
    hold = next(b for b in crs_node.root.iterate() if b.name == "Hold While Paused")
    assert hold.status == Status.RUNNING and hold.feedback_message == "paused"

    # Pause again mid-request: the ARS goal stays; the ARS is told to pause and honours it.
    assert _submit(crs_node, crs, "resume").final[0] == AckStage.COMPLETED
    crs.wait_for(lambda: rig.recorder.requests != [], timeout=10.0, what="first ARS request")
    _submit(crs_node, crs, "pause")
    first = rig.recorder.requests[0]
    time.sleep(0.6)
    assert first.outcome == "running" and len(rig.recorder.requests) == 1
    _submit(crs_node, crs, "resume")
    crs.wait_for(lambda: crs_node.ctx.model.tower_built, timeout=30.0, what="tower built")
    assert first.outcome == "succeeded"
    ids = rig.recorder.members("add_member")
    assert len(ids) == len(set(ids)) == 8


def test_a_lost_lifter_link_holds_the_build_as_a_fault_until_the_link_is_back(rig, crs, crs_node):
    rig.ars["ars_x"].hold_s = 3.0  # the ARS is paused before its request is done
    rig.lifter.trajectories.time_scale = 0.02
    _start(crs_node, crs)
    crs.wait_for(lambda: rig.recorder.requests != [], timeout=10.0, what="first ARS request")
    first = rig.recorder.requests[0]
    crs.wait_for(lambda: rig.vision.part_calls != [], timeout=10.0, what="its part inspected")
    rig.lifter.link_ok = False
    crs.wait_for(lambda: crs_node.ctx.run_state == RunState.FAULT, what="the link fault")
    progress = crs_node.progress()
    assert progress.fault.startswith("lifter link down (firmware does not answer)"), progress.fault
    assert crs_node.ctx.fault == ""  # not a fault that waits for the operator: it clears itself
    crs.wait_for(lambda: all(2 in a.commands for a in rig.ars.values()), what="PAUSE to the ARSs")
    time.sleep(3.0)  # as long as the ARS request: held (paused), not pre-empted, nothing new sent
    hold = next(b for b in crs_node.root.iterate() if b.name == "Hold While Paused")
    assert hold.status == Status.RUNNING and hold.feedback_message.startswith("held: lifter link down")
    assert first.outcome == "running" and len(rig.recorder.requests) == 1
    assert _submit(crs_node, crs, "resume").rejected  # nothing the operator paused
    refused = _submit(crs_node, crs, "set_blackboard_value", {"key": "clear_fault", "value": True})
    assert refused.rejected and "clears itself" in refused.stages[0][1]
    moved = _submit(crs_node, crs, "set_actuator_state", {"actuator": "lifter", "state": "safe"})
    assert moved.rejected and "held until the lifter link is back" in moved.stages[0][1]
    rig.ars["ars_x"].hold_s = 0.0  # the rest of the build at full speed

    rig.lifter.link_ok = True
    crs.wait_for(lambda: crs_node.ctx.run_state == RunState.RUNNING, what="the link back")
    crs.wait_for(lambda: all(3 in a.commands for a in rig.ars.values()), what="RESUME to the ARSs")
    crs.wait_for(lambda: crs_node.ctx.model.tower_built, timeout=30.0, what="tower built")
    assert first.outcome == "succeeded"
    ids = rig.recorder.members("add_member")
    assert len(ids) == len(set(ids)) == 8


def test_ars_failure_raises_a_fault_that_waits_for_help_until_cleared(rig, crs, crs_node):
    member = "bay1/vertical/x0_y0"
    rig.ars["ars_x"].fail[member] = "part slipped from the gripper"
    _start(crs_node, crs)
    crs.wait_for(lambda: crs_node.ctx.fault != "", timeout=20.0, what="fault")
    assert "part slipped from the gripper" in crs_node.ctx.fault and member in crs_node.ctx.fault
    assert crs_node.ctx.run_state == RunState.FAULT
    count = len(rig.recorder.requests)
    time.sleep(0.3)
    assert len(rig.recorder.requests) == count  # waiting for help: no new work
    wait = next(b for b in crs_node.root.iterate() if b.name == "Wait For Help")
    assert wait.status == Status.RUNNING
    # Actuator commands are allowed while waiting for help (the operator fixes things).
    assert _submit(
        crs_node, crs, "set_actuator_state", {"actuator": "lifter", "state": "crs_control"}
    ).final == (
        AckStage.COMPLETED,
        "",
    )
    del rig.ars["ars_x"].fail[member]
    _submit(crs_node, crs, "set_blackboard_value", {"key": "clear_fault", "value": True})
    crs.wait_for(lambda: crs_node.ctx.model.tower_built, timeout=30.0, what="tower built")
    assert crs_node.ctx.fault == "" and crs_node.ctx.board.get("clear_fault") is False
    placed = rig.recorder.members("add_member", outcome="succeeded")
    assert len(placed) == len(set(placed)) == 8


def test_stop_cancels_work_puts_the_lifter_in_safe_and_ends_the_node(rig, crs, crs_node):
    rig.ars["ars_x"].hold_s = 5.0
    _start(crs_node, crs)
    crs.wait_for(lambda: rig.vision.part_calls != [], timeout=10.0, what="ARS request past inspection")
    time.sleep(0.1)
    acks = _submit(crs_node, crs, "stop")
    assert acks.final[0] == AckStage.COMPLETED, acks.stages
    assert rig.lifter.mode_calls[-1] == 3  # Safe
    assert all(1 in a.commands for a in rig.ars.values())  # STOP forwarded
    crs.wait_for(lambda: rig.recorder.requests[0].outcome == "canceled", what="ARS goal canceled")
    assert crs_node.finished and crs_node.ctx.run_state == RunState.STOPPED
    assert _submit(crs_node, crs, "start").rejected


@pytest.mark.parametrize(
    ("params", "reason"),
    [
        ({"key": "no_such_key", "value": 1}, "unknown key 'no_such_key'"),
        ({"key": "started", "value": True}, "read-only"),
        ({"key": "tower_built", "value": True}, "read-only"),
        ({"key": "clear_fault", "value": True}, "no fault to clear"),
        ({"key": "lifter_speed", "value": "fast"}, "expected float"),
        ({"key": "lifter_speed", "value": 0.5}, "above the maximum"),
        ({"key": "inspection_attempts", "value": True}, "expected int"),
        ({"key": "cross_frame_ars", "value": "ars_z"}, "not one of"),
        ({"key": "lifter_speed"}, "needs 'key' and 'value'"),
    ],
)
def test_bad_blackboard_writes_are_refused_with_a_reason_and_change_nothing(crs, crs_node, params, reason):
    before = {k: crs_node.ctx.board.get(k) for k in crs_node.ctx.registry.keys}
    acks = _submit(crs_node, crs, "set_blackboard_value", params)
    assert acks.rejected and reason in acks.stages[0][1]
    assert {k: crs_node.ctx.board.get(k) for k in crs_node.ctx.registry.keys} == before


def test_blackboard_service_refuses_and_accepts_like_the_command(rig, crs, crs_node):
    from tlt_interfaces.msg import BlackboardValue
    from tlt_interfaces.srv import SetBlackboardValue

    client = rig.node.create_client(SetBlackboardValue, "/crs/set_blackboard_value")
    assert client.wait_for_service(timeout_sec=5.0)

    def call(key, value):
        future = client.call_async(SetBlackboardValue.Request(key=key, value=value))
        crs.wait_for(future.done, what="service answer")
        return future.result()

    refused = call("fault", BlackboardValue(type=3, string_value=""))
    assert not refused.accepted and "read-only" in refused.reason
    wrong = call("lifter_speed", BlackboardValue(type=0, bool_value=True))
    assert not wrong.accepted and "expected float" in wrong.reason
    ok = call("lifter_speed", BlackboardValue(type=2, float_value=0.015))
    assert ok.accepted and crs_node.ctx.board.get("lifter_speed") == 0.015


def test_actuator_commands_are_refused_while_building(rig, crs, crs_node):
    rig.lifter.trajectories.time_scale = 0.02
    _start(crs_node, crs)
    acks = _submit(crs_node, crs, "set_actuator_state", {"actuator": "lifter", "state": "safe"})
    assert acks.rejected and "refused while building" in acks.stages[0][1]
    _submit(crs_node, crs, "pause")
    acks = _submit(crs_node, crs, "set_actuator_state", {"actuator": "top_grippers", "state": "disengage"})
    assert acks.rejected and "refused while building (run state paused)" in acks.stages[0][1]
    assert rig.lifter.mode_calls.count(3) == 0


@pytest.mark.parametrize(
    ("name", "params", "reason"),
    [
        ("launch", {}, "unknown command 'launch'"),
        ("resume", {}, "not paused"),
        ("pause", {}, "not started"),
        ("set_actuator_state", {"actuator": "ee_x", "state": "open"}, "not driven by the CRS"),
        ("set_actuator_state", {"actuator": "lifter", "state": "up"}, "has no state 'up'"),
        ("set_actuator_state", {"actuator": "camera_mounts", "state": "move"}, "needs a numeric value"),
    ],
)
def test_commands_refused_in_the_wrong_state_say_why(rig, crs, crs_node, name, params, reason):
    acks = _submit(crs_node, crs, name, params)
    assert acks.rejected and reason in acks.stages[0][1]
    assert not crs_node.ctx.started and rig.lifter.mode_calls == []


def test_actuator_command_when_idle_drives_the_actuator(rig, crs, crs_node):
    acks = _submit(crs_node, crs, "set_actuator_state", {"actuator": "active_grippers", "state": "engage"})
    assert acks.final == (AckStage.COMPLETED, "")
    assert rig.active.engaged == [True] * 4
    acks = _submit(
        crs_node, crs, "set_actuator_state", {"actuator": "camera_mounts", "state": "move", "value": 0.3}
    )
    assert acks.final == (AckStage.COMPLETED, "") and rig.cameras.positions == [0.3, 0.3]


def test_start_is_refused_until_vision_says_it_can_place_its_cameras(rig, crs, crs_node):
    """Vision's services can be up before it has heard an arm's joint states (its subscription is
    matched on its own, after the CRS's): Start waits for vision's latched word, not the graph."""
    reason = "no joint state yet for ur_x_shoulder_pan_joint, ur_x_shoulder_lift_joint, ur_x_elbow_joint"
    rig.vision.readiness.say(reason)
    crs.wait_for(lambda: crs_node.ctx.not_ready() == f"vision: {reason}", what="vision not ready")
    refused = _submit(crs_node, crs, "start")
    assert refused.rejected and refused.stages[0][1] == f"not ready: vision: {reason}"
    rig.vision.readiness.say("")
    crs.wait_for(lambda: not crs_node.ctx.not_ready(), what="vision ready")
    final = _start(crs_node, crs).final
    assert final[0] == AckStage.COMPLETED, final[1]


def test_start_twice_is_refused(rig, crs, crs_node):
    _start(crs_node, crs)
    acks = _submit(crs_node, crs, "start")
    assert acks.rejected and "already started" in acks.stages[0][1]


def test_start_is_refused_until_vision_is_up(rig, crs, crs_node):
    rig.vision.withdraw()
    # Both services gone from the graph: the graph learns of each on its own.
    gone = (ros_names.VISION_INSPECT_PART, ros_names.VISION_INSPECT_BAY)
    crs.wait_for(lambda: all(s in crs_node.ctx.not_ready() for s in gone), what="vision gone from the graph")
    refused = _submit(crs_node, crs, "start")
    assert refused.rejected
    assert (
        refused.stages[0][1] == f"not ready: vision: {ros_names.VISION_INSPECT_PART}, "
        f"vision: {ros_names.VISION_INSPECT_BAY} not up"
    )
    rig.vision.serve()
    crs.wait_for(lambda: not crs_node.ctx.not_ready(), what="vision back")
    final = _start(crs_node, crs).final
    assert final[0] == AckStage.COMPLETED, final[1]


def test_the_tree_ticks_on_while_ros_time_stands_still(rig, crs, crs_node, stop_ros_time):
    # On hardware ROS time is the system clock; set back, it stands still for a timer on it, which
    # stopped the tree for as long as the step (its progress and the ground telemetry are on the
    # same kind of timer, tlt_common.ros.periodic_timer).
    ticks: list[int] = []
    crs_node.tick_listeners.append(lambda: ticks.append(1))
    stop_ros_time(crs_node)
    crs.wait_for(lambda: len(ticks) >= 5, what="ticks while ROS time stands still")
    _start(crs_node, crs)
    crs.wait_for(lambda: rig.recorder.requests, what="a request sent while ROS time stands still")


def test_every_actuator_state_the_ground_is_offered_is_one_the_crs_accepts_when_idle(crs_node):
    """The GSW offers the definitions' actuator table (GUI and CLI); the CRS takes all of it."""
    from tlt_common.ccsds.definitions import load_definitions

    table = load_definitions().actuators
    assert table, "the definitions offer no actuator"
    for actuator in table.values():
        for state in actuator.states:
            params = {"actuator": actuator.name, "state": state}
            if state in actuator.value_states:
                params["value"] = actuator.value_minimum
            assert crs_node.processor.check("set_actuator_state", params) is None, params


def test_the_crs_refuses_to_start_on_an_actuator_table_it_cannot_drive(tmp_path):
    import yaml

    from tlt_common.ccsds.definitions import DEFAULT_PATH, load_definitions
    from tlt_common.config_schema import ConfigError
    from tlt_crs.commands import check_actuator_table

    doc = yaml.safe_load(DEFAULT_PATH.read_text())
    doc["actuators"]["active_grippers"]["states"].append("raise")
    path = tmp_path / "definitions.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as err:
        check_actuator_table(load_definitions(path))
    assert (err.value.source, err.value.key) == (str(path), "actuators.active_grippers.states")
    assert "cannot drive active_grippers to 'raise'" in err.value.reason
    doc["actuators"]["ee_x"] = {"states": ["open"]}
    doc["actuators"]["active_grippers"]["states"].remove("raise")
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match="drives no actuator 'ee_x'"):
        check_actuator_table(load_definitions(path))


def test_a_write_to_an_ars_key_is_forwarded_to_that_ars_and_applied_there(rig, crs, crs_node):
    before_y = rig.ars["ars_y"].config.raw["arm"]["settle_s"]
    acks = _submit(crs_node, crs, "set_blackboard_value", {"key": "ars_x/settle_s", "value": 2.5})
    assert [stage for stage, _ in acks.stages] == [AckStage.ACCEPTED, AckStage.COMPLETED], acks.stages
    assert rig.ars["ars_x"].config.raw["arm"]["settle_s"] == 2.5
    assert rig.ars["ars_y"].config.raw["arm"]["settle_s"] == before_y
    acks = _submit(crs_node, crs, "set_blackboard_value", {"key": "ars_y/motion_attempts", "value": 4})
    assert (
        acks.final == (AckStage.COMPLETED, "") and rig.ars["ars_y"].config.raw["arm"]["motion_attempts"] == 4
    )


@pytest.mark.parametrize(
    ("params", "reason"),
    [
        ({"key": "ars_x/settle_s", "value": 20.0}, "ars_x: key 'settle_s': 20.0 is above the maximum 10"),
        ({"key": "ars_y/velocity_scale", "value": 0.2}, "ars_y: unknown key 'velocity_scale'"),
        ({"key": "ars_x/motion_attempts", "value": "many"}, "expected int, got str"),
    ],
)
def test_a_write_to_an_ars_key_outside_its_whitelist_is_refused_on_arrival(
    rig, crs, crs_node, params, reason
):
    before = {ars: dict(a.config.raw["arm"]) for ars, a in rig.ars.items()}
    acks = _submit(crs_node, crs, "set_blackboard_value", params)
    assert acks.rejected and reason in acks.stages[0][1], acks.stages
    assert {ars: dict(a.config.raw["arm"]) for ars, a in rig.ars.items()} == before


def test_an_ars_that_refuses_a_write_fails_the_command_with_its_reason(rig, crs, crs_node):
    import dataclasses

    registry = rig.ars["ars_x"].ground_writes.registry
    registry.keys["fire_s"] = dataclasses.replace(registry.keys["fire_s"], writable=False)
    acks = _submit(crs_node, crs, "set_blackboard_value", {"key": "ars_x/fire_s", "value": 1.0})
    assert acks.stages[0][0] == AckStage.ACCEPTED  # the CRS's copy of the whitelist allows it
    assert acks.final == (AckStage.FAILED, "ars_x: key 'fire_s' is read-only"), acks.stages
    assert rig.ars["ars_x"].config.raw["end_effector"]["fire_s"] == 0.5


def test_tower_model_corrections_from_the_ground_are_applied_under_the_models_rules(crs, crs_node):
    model = crs_node.ctx.model
    events: list[tuple[str, str]] = []
    crs_node.ctx.event_listeners.append(lambda severity, code, text: events.append((code, text)))
    acks = _submit(
        crs_node, crs, "set_blackboard_value", {"key": "tower/bay1/cross_frame", "value": "placed"}
    )
    assert acks.final == (AckStage.COMPLETED, ""), acks.stages
    assert model.state("bay1/cross_frame") == 1  # PLACED
    assert ("TOWER_CORRECTED", "bay1/cross_frame marked placed from the ground: now PLACED") in events
    fewer = model.remaining["vertical_dispenser_x"] - 1
    acks = _submit(
        crs_node, crs, "set_blackboard_value", {"key": "dispenser/vertical_dispenser_x", "value": fewer}
    )
    assert acks.final == (AckStage.COMPLETED, "") and model.remaining["vertical_dispenser_x"] == fewer
    assert any(code == "DISPENSER_CORRECTED" for code, _ in events)
    progress = crs_node.progress()
    assert next(d.remaining for d in progress.dispensers if d.name == "vertical_dispenser_x") == fewer


@pytest.mark.parametrize(
    ("params", "reason"),
    [
        ({"key": "tower/bay1/cross_frame", "value": "unplaced"}, "'bay1/cross_frame' is already NOT_PLACED"),
        ({"key": "tower/bay1/cross_frame", "value": 1}, "a member's mark is a string"),
        ({"key": "tower/bay7/cross_frame", "value": "placed"}, "unknown member 'bay7/cross_frame'"),
        ({"key": "tower/bay1/cross_frame", "value": "gone"}, "unknown mark 'gone'"),
        ({"key": "dispenser/vertical_dispenser_x", "value": 99}, "can hold at most"),
        ({"key": "dispenser/nowhere", "value": 1}, "unknown dispenser 'nowhere'"),
    ],
)
def test_tower_model_corrections_against_its_rules_are_refused_with_the_reason(crs, crs_node, params, reason):
    revision = crs_node.ctx.model.revision
    acks = _submit(crs_node, crs, "set_blackboard_value", params)
    assert acks.rejected and reason in acks.stages[0][1], acks.stages
    assert crs_node.ctx.model.revision == revision


def test_tower_model_corrections_are_refused_while_building(rig, crs, crs_node):
    rig.ars["ars_x"].hold_s = 2.0
    _start(crs_node, crs)
    acks = _submit(
        crs_node, crs, "set_blackboard_value", {"key": "dispenser/vertical_dispenser_x", "value": 0}
    )
    assert acks.rejected, acks.stages
    assert acks.stages[0][1].startswith(
        "refused while building (run state running): the tree keeps the tower model"
    )
