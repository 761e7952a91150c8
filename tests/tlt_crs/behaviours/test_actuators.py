"""Raise Payload (Fig. 18), Lower Lifter (Fig. 19) and their steps, each ticked on its own against
stand-ins of the lifter and gripper driver topics, services and trajectory actions."""

from __future__ import annotations

from py_trees.common import Status

from tlt_common.mission.schema import load_mission
from tlt_crs.behaviours.actuators import Actuators


def test_raise_payload_follows_fig_18_and_is_confirmed_by_sensors(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    subtree = Actuators(ctx).raise_payload()
    crs.wait_for(lambda: ctx.cache.latest("/lifter/state") is not None, what="lifter state")
    assert crs.tick_until(subtree) == Status.SUCCESS
    assert rig.active.engaged == [True] * 4
    assert rig.top.engaged == [False] * 4
    assert rig.lifter.state == 2 and rig.lifter.mode_calls == [2]
    raised = ctx.config.lifter.lowered_m + ctx.mission.bay_height  # one bay above the build level
    assert all(abs(p - raised) < 1e-9 for p in rig.lifter.positions)
    # Order of Fig. 18: Active engaged before Top released, lifter moved last.
    assert rig.active.commands[0] == [1.5] * 4
    assert rig.top.commands[0] == [0.0] * 4


def test_lower_lifter_follows_fig_19(rig, crs, tmp_path):
    # The devices' states first: a context made before could still hear the stand-ins' old ones.
    rig.top.set_engaged(False)
    rig.active.set_engaged(True)
    rig.lifter.positions = [0.8] * 4
    ctx = crs.make_context(rig, crs.fast_config(tmp_path))
    subtree = Actuators(ctx).lower_lifter()
    assert crs.tick_until(subtree) == Status.SUCCESS
    assert rig.top.engaged == [True] * 4 and rig.active.engaged == [False] * 4
    assert all(abs(p - ctx.config.lifter.lowered_m) < 1e-9 for p in rig.lifter.positions)


def test_steps_already_true_by_the_sensors_are_skipped(rig, crs, tmp_path):
    config = crs.fast_config(tmp_path)
    rig.active.set_engaged(True)
    rig.top.set_engaged(False)
    rig.lifter.state = 2
    rig.lifter.positions = [config.lifter.lowered_m + load_mission(config.mission).bay_height] * 4
    ctx = crs.make_context(rig, config)
    subtree = Actuators(ctx).raise_payload()  # subscribes to the sensor topics
    for topic in ("/lifter/state", "/active_grippers/state", "/top_grippers/state"):
        crs.wait_for(lambda topic=topic: ctx.cache.latest(topic) is not None, what=topic)
    assert crs.tick_until(subtree) == Status.SUCCESS
    assert rig.active.commands == [] and rig.top.commands == []
    assert rig.lifter.mode_calls == [] and rig.lifter.trajectories.goals == []


def test_lifter_that_does_not_move_fails_with_the_sensor_state(rig, crs, tmp_path):
    ctx = crs.make_context(rig, crs.fast_config(tmp_path, actuator_s=0.5))
    rig.lifter.state = 2
    rig.lifter.trajectories.apply = lambda names, positions: None  # goal "succeeds", nothing moves
    subtree = Actuators(ctx).lifter_move("Raise", 0.8)
    crs.wait_for(lambda: ctx.cache.latest("/lifter/state") is not None, what="lifter state")
    assert crs.tick_until(subtree) == Status.FAILURE
    wait = subtree.children[1].children[1]
    assert "did not confirm" in wait.feedback_message and "0.1" in wait.feedback_message


def test_missing_gripper_state_is_a_timeout_not_a_hang(ros, crs, tmp_path):
    rig = crs.Rig(with_drivers=False, with_ars=False)
    try:
        ctx = crs.make_context(rig, crs.fast_config(tmp_path, service_s=0.3, actuator_s=0.3))
        subtree = Actuators(ctx).top_grippers(True)
        assert crs.tick_until(subtree, timeout=5.0) == Status.FAILURE
        assert "no message on '/top_grippers/state'" in subtree.children[1].children[1].feedback_message
    finally:
        rig.close()


def test_a_raise_longer_than_the_actuator_bound_is_waited_for(rig, crs, tmp_path):
    """A raise by a bay (0.75 m at the default 0.01 m/s) is a 75 s trajectory: its result is awaited
    for that long plus ``actuator_s``, not ``actuator_s`` alone."""
    ctx = crs.make_context(rig, crs.fast_config(tmp_path, actuator_s=0.5))
    rig.lifter.state = 2
    start = rig.lifter.positions[0]
    rig.lifter.trajectories.time_scale = 0.02  # the stand-in takes 1.5 s: three times actuator_s
    subtree = Actuators(ctx).lifter_move("Raise", start + 0.75)
    crs.wait_for(lambda: ctx.cache.latest("/lifter/state") is not None, what="lifter state")
    assert crs.tick_until(subtree) == Status.SUCCESS, subtree.tip().feedback_message
    assert all(abs(p - (start + 0.75)) < 1e-9 for p in rig.lifter.positions)
