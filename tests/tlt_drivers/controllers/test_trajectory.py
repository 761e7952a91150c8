"""JointTrajectoryController logic: interpolation, tolerances, goal time, replacement, refusal."""

from __future__ import annotations

import pytest

from tlt_drivers.controllers import trajectory as jtc
from tlt_drivers.controllers.trajectory import (
    GoalStatus,
    JointTrajectoryController,
    TrajectoryGoal,
    TrajectoryPoint,
    sample,
)

LIMITS = {"a": (-1.0, 1.0), "b": (-2.0, 2.0)}


def make(**kw) -> JointTrajectoryController:
    return JointTrajectoryController(
        ["a", "b"], LIMITS, path_tolerance=0.1, goal_tolerance=0.01, goal_time_tolerance=0.5, **kw
    )


def goal(*points, names=("a", "b"), **kw) -> TrajectoryGoal:
    return TrajectoryGoal(tuple(names), tuple(TrajectoryPoint(*p) for p in points), **kw)


def test_linear_interpolation_from_start_state():
    g = goal((1.0, (0.5, 1.0)), (2.0, (1.0, 0.0)))
    pos, vel = sample(g, (0.0, 0.0), 0.5)
    assert pos == pytest.approx({"a": 0.25, "b": 0.5}) and vel == pytest.approx({"a": 0.5, "b": 1.0})
    pos, _ = sample(g, (0.0, 0.0), 1.5)
    assert pos == pytest.approx({"a": 0.75, "b": 0.5})
    assert sample(g, (0.0, 0.0), 5.0)[0] == {"a": 1.0, "b": 0.0}


def test_cubic_interpolation_meets_point_velocities():
    g = goal((1.0, (1.0, 0.0), (0.0, 0.0)))
    pos, vel = sample(g, (0.0, 0.0), 0.5)
    assert pos["a"] == pytest.approx(0.5) and vel["a"] == pytest.approx(1.5)  # smoothstep mid-speed
    assert sample(g, (0.0, 0.0), 0.0)[1]["a"] == pytest.approx(0.0)
    assert sample(g, (0.0, 0.0), 1.0)[1]["a"] == pytest.approx(0.0)
    g2 = goal((1.0, (1.0, 0.0), (2.0, 0.0)))
    assert sample(g2, (0.0, 0.0), 1.0)[1]["a"] == pytest.approx(2.0)


def test_tracking_goal_succeeds_and_holds_final_point():
    c = make()
    run = c.start(goal((1.0, (0.5, -0.5))), 10.0, {"a": 0.0, "b": 0.0})
    actual = {"a": 0.0, "b": 0.0}
    for k in range(21):  # a servo one 50 ms cycle behind the command
        actual = c.update(10.0 + 0.05 * k, actual)
        assert run.status == GoalStatus.RUNNING
    assert actual == pytest.approx({"a": 0.5, "b": -0.5})
    cmd = c.update(11.05, {"a": 0.5, "b": -0.5})
    assert run.status == GoalStatus.SUCCEEDED and run.error_code == jtc.SUCCESSFUL
    assert cmd == {"a": 0.5, "b": -0.5}
    assert c.update(20.0, {"a": 0.5, "b": -0.5}) == {"a": 0.5, "b": -0.5}


def test_path_tolerance_violation_aborts_and_holds_actual():
    c = make()
    run = c.start(goal((1.0, (1.0, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    c.update(0.1, {"a": 0.0, "b": 0.0})  # desired 0.1, actual 0.0: within 0.1
    cmd = c.update(0.5, {"a": 0.0, "b": 0.0})  # desired 0.5: 0.5 off
    assert run.status == GoalStatus.ABORTED and run.error_code == jtc.PATH_TOLERANCE_VIOLATED
    assert "joint 'a'" in run.error_string
    assert cmd == {"a": 0.0, "b": 0.0}


def test_negative_tolerance_means_no_limit():
    c = make()
    run = c.start(goal((1.0, (1.0, 0.0)), path_tolerance={"a": -1.0}), 0.0, {"a": 0.0, "b": 0.0})
    c.update(0.5, {"a": 0.0, "b": 0.0})
    assert run.status == GoalStatus.RUNNING


def test_goal_tolerance_after_goal_time_aborts():
    c = make()
    run = c.start(goal((1.0, (0.5, 0.0)), path_tolerance={"a": -1.0}), 0.0, {"a": 0.0, "b": 0.0})
    c.update(1.2, {"a": 0.45, "b": 0.0})
    assert run.status == GoalStatus.RUNNING  # still within the goal time tolerance
    c.update(1.6, {"a": 0.45, "b": 0.0})
    assert run.status == GoalStatus.ABORTED and run.error_code == jtc.GOAL_TOLERANCE_VIOLATED
    assert "joint 'a'" in run.error_string and "0.0500" in run.error_string


def test_a_joint_passing_through_its_goal_at_speed_has_not_arrived():
    """With the joints' velocities given and a goal velocity tolerance (ros2_control's
    stopped_velocity_tolerance), a goal succeeds only once the arm is at rest at it: the ARS
    measures the held part with its EE cameras as soon as the move succeeds."""
    c = make(goal_velocity_tolerance=0.01)
    run = c.start(goal((1.0, (0.5, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    at_goal = {"a": 0.495, "b": 0.0}  # within the 0.01 goal tolerance
    c.update(1.1, at_goal, {"a": 0.4, "b": 0.0})
    assert run.status == GoalStatus.RUNNING
    c.update(1.2, at_goal, {"a": 0.005, "b": 0.0})
    assert run.status == GoalStatus.SUCCEEDED
    # Without velocities (a driver that reads none) the goal tolerance alone decides, as before.
    c2 = make(goal_velocity_tolerance=0.01)
    run = c2.start(goal((1.0, (0.5, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    c2.update(1.1, at_goal)
    assert run.status == GoalStatus.SUCCEEDED


def test_an_arm_ringing_about_its_goal_is_not_at_rest_at_a_turn():
    """At each turn of an arm ringing about its goal its speed passes through zero: with a settle
    time the joints must stay within their tolerances that long, and a swing out starts it again.
    A goal settling when the goal time runs out is not aborted for it."""
    c = make(goal_velocity_tolerance=0.01, goal_settle_s=0.1)
    run = c.start(goal((1.0, (0.5, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    at, still, swinging = {"a": 0.498, "b": 0.0}, {"a": 0.0, "b": 0.0}, {"a": 0.05, "b": 0.0}
    c.update(1.00, at, still)  # a turn
    c.update(1.05, at, swinging)
    c.update(1.10, at, still)  # the next turn
    c.update(1.15, at, still)
    assert run.status == GoalStatus.RUNNING
    c.update(1.20, at, still)
    assert run.status == GoalStatus.SUCCEEDED
    late = c.start(goal((1.0, (0.5, 0.0))), 10.0, {"a": 0.0, "b": 0.0})
    c.update(11.45, at, still)
    c.update(11.55, at, still)  # past the 0.5 s goal time tolerance, settling since 11.45
    assert late.status == GoalStatus.SUCCEEDED


def test_an_arm_still_moving_after_the_goal_time_aborts_saying_so():
    c = make()  # no default: the goal's own velocity tolerance applies
    g = goal((1.0, (0.5, 0.0)), goal_velocity_tolerance={"a": 0.02})
    run = c.start(g, 0.0, {"a": 0.0, "b": 0.0})
    c.update(1.2, {"a": 0.5, "b": 0.0}, {"a": 0.1, "b": 0.0})
    assert run.status == GoalStatus.RUNNING
    c.update(1.6, {"a": 0.5, "b": 0.0}, {"a": 0.1, "b": 0.0})
    assert run.status == GoalStatus.ABORTED and run.error_code == jtc.GOAL_TOLERANCE_VIOLATED
    assert "joint 'a' still moves at 0.1000/s" in run.error_string and "tolerance 0.02" in run.error_string
    # None given and no default: velocities are not judged.
    plain = make()
    run = plain.start(goal((1.0, (0.5, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    plain.update(1.2, {"a": 0.5, "b": 0.0}, {"a": 0.1, "b": 0.0})
    assert run.status == GoalStatus.SUCCEEDED


def test_goal_time_tolerance_from_goal_overrides_default():
    c = make()
    run = c.start(
        goal((1.0, (0.5, 0.0)), path_tolerance={"a": -1.0}, goal_time_tolerance=2.0),
        0.0,
        {"a": 0.0, "b": 0.0},
    )
    c.update(2.5, {"a": 0.45, "b": 0.0})
    assert run.status == GoalStatus.RUNNING
    c.update(2.6, {"a": 0.5, "b": 0.0})
    assert run.status == GoalStatus.SUCCEEDED


def test_new_goal_preempts_the_running_one():
    c = make()
    first = c.start(goal((2.0, (1.0, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    c.update(0.5, {"a": 0.25, "b": 0.0})
    second = c.start(goal((1.0, (-0.5,)), names=("a",)), 0.5, {"a": 0.25, "b": 0.0})
    assert first.status == GoalStatus.PREEMPTED and "replaced" in first.error_string
    cmd = c.update(1.0, {"a": -0.125, "b": 0.0})
    assert cmd["a"] == pytest.approx(-0.125) and cmd["b"] == 0.0  # b holds
    assert second.status == GoalStatus.RUNNING


@pytest.mark.parametrize(
    ("g", "code", "words"),
    [
        (goal((1.0, (0.5,)), names=("z",)), jtc.INVALID_JOINTS, "unknown joint"),
        (goal((1.0, (0.5, 0.5)), names=("a", "a")), jtc.INVALID_JOINTS, "twice"),
        (goal(), jtc.INVALID_GOAL, "no points"),
        (goal((1.0, (0.5, 0.0)), (1.0, (0.6, 0.0))), jtc.INVALID_GOAL, "not after"),
        (goal((1.0, (0.5,))), jtc.INVALID_GOAL, "1 positions for 2 joints"),
        (goal((1.0, (1.5, 0.0))), jtc.INVALID_GOAL, "joint 'a' position 1.5 above upper limit 1.0"),
        (goal((1.0, (0.0, -3.0))), jtc.INVALID_GOAL, "joint 'b' position -3.0 below lower limit -2.0"),
        (goal((1.0, (float("nan"), 0.0))), jtc.INVALID_GOAL, "not a number"),
    ],
)
def test_invalid_goals_are_aborted_with_a_reason_and_do_not_preempt(g, code, words):
    c = make()
    running = c.start(goal((2.0, (1.0, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    bad = c.start(g, 0.1, {"a": 0.0, "b": 0.0})
    assert bad.status == GoalStatus.ABORTED and bad.error_code == code and words in bad.error_string
    assert running.status == GoalStatus.RUNNING


def test_motion_gate_refuses_with_its_reason():
    c = make(motion_gate=lambda: "ee_x is not calibrated")
    run = c.start(goal((1.0, (0.5, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    assert run.status == GoalStatus.ABORTED and run.error_code == jtc.HARDWARE_FAULT
    assert run.error_string == "ee_x is not calibrated"


def test_fault_and_cancel_stop_where_the_joints_are():
    c = make()
    run = c.start(goal((1.0, (1.0, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    c.fault("link lost", {"a": 0.3, "b": 0.0})
    assert run.error_code == jtc.HARDWARE_FAULT and c.update(0.5, {"a": 0.3, "b": 0.0})["a"] == 0.3
    run2 = c.start(goal((1.0, (1.0, 0.0))), 1.0, {"a": 0.3, "b": 0.0})
    c.cancel({"a": 0.4, "b": 0.0})
    assert run2.status == GoalStatus.CANCELED and c.update(1.5, {"a": 0.4, "b": 0.0})["a"] == 0.4


def test_a_stalled_cycle_moves_the_trajectory_on_by_at_most_max_time_step():
    # A control loop that got no CPU for 0.3 s: without a bound the desired position would jump
    # 0.3 rad ahead of an arm that got no commands meanwhile and abort the goal on the path limit.
    c = make(max_time_step=0.05)
    run = c.start(goal((1.0, (1.0, 0.0))), 10.0, {"a": 0.0, "b": 0.0})
    actual = c.update(10.02, {"a": 0.0, "b": 0.0})
    cmd = c.update(10.32, actual)
    assert cmd["a"] == pytest.approx(0.07)  # 0.02 s, then the bounded 0.05 s
    assert run.status == GoalStatus.RUNNING
    unbounded = make()
    run = unbounded.start(goal((1.0, (1.0, 0.0))), 10.0, {"a": 0.0, "b": 0.0})
    actual = unbounded.update(10.02, {"a": 0.0, "b": 0.0})
    unbounded.update(10.32, actual)
    assert run.status == GoalStatus.ABORTED and run.error_code == jtc.PATH_TOLERANCE_VIOLATED


def test_an_arm_late_along_its_path_is_not_off_it_within_the_lag_window():
    # The arm keeps to the path 0.3 s behind it: on the path, late; then it stops moving: off it.
    c = make(path_lag_window=0.5)
    run = c.start(goal((2.0, (1.0, 0.0))), 0.0, {"a": 0.0, "b": 0.0})
    for k in range(1, 11):
        t = 0.1 * k
        c.update(t, {"a": max(t - 0.3, 0.0) / 2.0, "b": 0.0})
    assert run.status == GoalStatus.RUNNING
    for k in range(11, 18):
        c.update(0.1 * k, {"a": 0.35, "b": 0.0})
    assert run.status == GoalStatus.ABORTED and run.error_code == jtc.PATH_TOLERANCE_VIOLATED
    assert "nor up to 0.5 s earlier" in run.error_string
