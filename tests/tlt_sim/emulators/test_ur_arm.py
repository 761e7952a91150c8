"""The emulated arm's motion, stepped with an explicit clock."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tlt_sim.emulators import ur_kinematics as kin
from tlt_sim.emulators.ur_arm import HOME, UR10E_MAX_VELOCITY, UR10eArm

DT = 0.002


def run(arm: UR10eArm, seconds: float) -> list[list[float]]:
    trace = []
    for _ in range(round(seconds / DT)):
        arm.step(DT)
        trace.append(arm.velocities())
    return trace


def test_move_joints_follows_a_synchronised_trapezoid() -> None:
    arm = UR10eArm(HOME)
    target = list(HOME)
    target[0] += 1.0  # lead joint: 1 rad at v=0.5, a=1 -> 0.5 s ramp, 1.5 s cruise: 2.5 s
    target[3] += 0.5
    arm.move_joints(target, v=0.5, a=1.0)
    trace = run(arm, 2.4)
    assert arm.moving
    assert max(abs(v[0]) for v in trace) == pytest.approx(0.5, abs=1e-9)
    # The second joint is scaled to finish with the lead: half its speed all the way.
    assert all(v[3] == pytest.approx(v[0] / 2) for v in trace)
    run(arm, 0.12)
    assert not arm.moving
    assert arm.positions() == pytest.approx(target)
    assert arm.velocities() == [0.0] * 6


def test_move_joints_respects_the_joint_speed_limit() -> None:
    arm = UR10eArm(HOME)
    target = list(HOME)
    target[0] += 3.0
    arm.move_joints(target, v=3.0, a=10.0)
    trace = run(arm, 2.0)
    assert max(abs(v[0]) for v in trace) <= UR10E_MAX_VELOCITY[0] + 1e-9


def test_move_linear_keeps_the_tcp_on_the_segment() -> None:
    arm = UR10eArm(HOME)
    start = np.array(arm.tcp_pose())
    goal = start.copy()
    goal[0] += 0.1
    goal[2] -= 0.1
    arm.move_linear(goal.tolist(), v=0.2, a=1.0)
    for _ in range(2000):
        arm.step(DT)
        p = np.array(arm.tcp_pose()[:3])
        # distance of the TCP from the line through start and goal
        axis = goal[:3] - start[:3]
        d = np.linalg.norm(np.cross(p - start[:3], axis)) / np.linalg.norm(axis)
        assert d < 1e-6
        if not arm.moving:
            break
    assert not arm.moving
    assert arm.tcp_pose() == pytest.approx(goal.tolist(), abs=1e-6)


def test_unreachable_move_linear_is_refused_before_moving() -> None:
    arm = UR10eArm(HOME)
    with pytest.raises(kin.IKError):
        arm.move_linear([3.0, 0.0, 0.5, 0.0, math.pi, 0.0], v=0.2, a=1.0)
    assert not arm.moving


def test_servo_tracks_a_moving_target_with_a_bounded_lag() -> None:
    arm = UR10eArm(HOME)
    q = list(HOME)
    errors = []
    for k in range(1000):
        q[1] = HOME[1] + 0.3 * math.sin(k * DT * 2)
        arm.servo(q, lookahead=0.03, gain=2000)
        arm.step(DT)
        errors.append(abs(arm.positions()[1] - q[1]))
    assert max(errors[100:]) < 0.02


def test_stop_decelerates_at_the_given_rate_and_halt_is_immediate() -> None:
    arm = UR10eArm(HOME)
    arm.speed([0.5, 0, 0, 0, 0, 0], a=5.0)
    run(arm, 0.5)
    assert arm.velocities()[0] == pytest.approx(0.5)
    arm.stop(deceleration=2.0)
    run(arm, 0.2)
    assert arm.velocities()[0] == pytest.approx(0.1, abs=1e-6)
    run(arm, 0.1)
    assert not arm.moving
    arm.speed([0.5, 0, 0, 0, 0, 0], a=5.0)
    run(arm, 0.5)
    arm.halt()
    assert arm.velocities() == [0.0] * 6 and not arm.moving


def test_targets_outside_the_joint_range_are_refused() -> None:
    arm = UR10eArm(HOME)
    with pytest.raises(ValueError, match="joint 2"):
        arm.move_joints([0, 0, 7.0, 0, 0, 0], v=1, a=1)
    with pytest.raises(ValueError):
        arm.servo([0, 0, float("nan"), 0, 0, 0], lookahead=0.1, gain=300)


def test_twin_can_overwrite_the_measured_state() -> None:
    arm = UR10eArm(HOME)
    arm.set_state([0.1] * 6, [0.2] * 6)
    assert arm.positions() == [0.1] * 6 and arm.velocities() == [0.2] * 6


def test_the_tcp_pose_follows_the_joints_and_the_tool_whatever_changes_them() -> None:
    arm = UR10eArm(HOME)
    at_home = arm.tcp_pose()
    assert at_home == pytest.approx(kin.forward(np.array(HOME), [0.0] * 6))
    at_home.append(99.0)  # a caller's copy: the arm's pose is not changed through it
    assert len(arm.tcp_pose()) == 6
    arm.move_joints([h + 0.3 for h in HOME], 1.0, 1.0)
    run(arm, 0.2)
    assert arm.tcp_pose() == pytest.approx(kin.forward(np.array(arm.positions()), [0.0] * 6))
    arm.set_state([0.1] * 6)
    assert arm.tcp_pose() == pytest.approx(kin.forward(np.array([0.1] * 6), [0.0] * 6))
    arm.set_tcp([0.0, 0.0, 0.2, 0.0, 0.0, 0.0])
    assert arm.tcp_pose() == pytest.approx(kin.forward(np.array([0.1] * 6), [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]))
