"""The lifter's velocity trajectory controller: counts/s from trajectories, tolerances, limits.

The plant is a plain integrator of the commanded counts/s (what the firmware does with them),
stepped at the command period, so these tests are exact and fast.
"""

from __future__ import annotations

import pytest

from tlt_drivers.lifter.config import ControllerConfig, JointConfig
from tlt_drivers.lifter.velocity_trajectory_controller import (
    GoalRejected,
    Outcome,
    TrajectoryPoint,
    VelocityTrajectoryController,
)

CPM = 200_000.0
JOINTS = tuple(JointConfig(f"j{i}", CPM, 0.0, 1.2, 0.05) for i in range(4))
NAMES = [j.name for j in JOINTS]
DT = 0.02


def make() -> VelocityTrajectoryController:
    return VelocityTrajectoryController(JOINTS, ControllerConfig(position_gain=2.0))


def simulate(ctl, positions, t0=0.0, duration=30.0, stuck=(), speed_factor=1.0):
    """Integrate commands until the goal ends; returns (final step, positions, commands seen)."""
    t = t0
    seen = []
    step = None
    while t < t0 + duration:
        step = ctl.update(t, positions)
        seen.append(step.commands)
        if step.outcome != Outcome.RUNNING:
            break
        for i, c in enumerate(step.commands):
            if i not in stuck:
                positions[i] += c / CPM * DT * speed_factor
        t += DT
    return step, positions, seen


def test_raises_the_lifter_to_the_goal_in_counts_per_second() -> None:
    ctl = make()
    pos = [0.1] * 4
    ctl.start(NAMES, [TrajectoryPoint(4.0, (0.2,) * 4)], 0.0, pos)
    step, pos, seen = simulate(ctl, pos)
    assert step.outcome == Outcome.SUCCEEDED
    assert all(abs(p - 0.2) <= 0.002 for p in pos)
    # the trajectory's velocity, 0.1 m in 4 s = 0.025 m/s, is 5000 counts/s on the wire
    assert seen[len(seen) // 2] == pytest.approx([5000] * 4, abs=100)
    assert all(isinstance(c, int) for c in seen[3])
    assert step.commands == [0, 0, 0, 0]


def test_hermite_points_with_velocities_are_followed() -> None:
    ctl = make()
    pos = [0.5] * 4
    points = [
        TrajectoryPoint(0.0, (0.5,) * 4, (0.0,) * 4),
        TrajectoryPoint(2.0, (0.54,) * 4, (0.03,) * 4),
        TrajectoryPoint(4.0, (0.6,) * 4, (0.0,) * 4),
    ]
    ctl.start(NAMES, points, 0.0, pos)
    desired, vel = ctl._sample(2.0)
    assert desired == pytest.approx([0.54] * 4) and vel == pytest.approx([0.03] * 4)
    step, pos, _ = simulate(ctl, pos)
    assert step.outcome == Outcome.SUCCEEDED


def test_joints_not_in_the_goal_get_zero() -> None:
    ctl = make()
    ctl.start(["j1", "j3"], [TrajectoryPoint(2.0, (0.3, 0.3))], 0.0, [0.2] * 4)
    step = ctl.update(1.0, [0.2, 0.25, 0.2, 0.25])
    assert step.commands[0] == 0 and step.commands[2] == 0
    assert step.commands[1] > 0 and step.commands[3] > 0


@pytest.mark.parametrize(
    ("points", "match"),
    [
        (
            [TrajectoryPoint(30.0, (0.2, 0.2, 1.3, 0.2))],
            r"joint j2 position 1\.3 m exceeds its limit max_position_m = 1\.2",
        ),
        (
            [TrajectoryPoint(30.0, (-0.1, 0.2, 0.2, 0.2))],
            r"joint j0 position -0\.1 m is below its limit min_position_m",
        ),
        (
            [TrajectoryPoint(1.0, (0.9, 0.2, 0.2, 0.2))],
            r"joint j0 needs .* m/s, above its limit max_velocity_m_s = 0\.05",
        ),
        (
            [TrajectoryPoint(10.0, (0.3,) * 4, (0.0, 0.0, 0.0, 0.08))],
            r"joint j3 velocity 0\.08 m/s exceeds its limit max_velocity_m_s",
        ),
        ([], "no points"),
        ([TrajectoryPoint(2.0, (0.2,) * 4), TrajectoryPoint(1.0, (0.2,) * 4)], "does not increase"),
        ([TrajectoryPoint(2.0, (0.2,) * 3)], "3 positions for 4 joints"),
    ],
)
def test_bad_goals_are_rejected_naming_joint_and_limit(points, match) -> None:
    ctl = make()
    with pytest.raises(GoalRejected, match=match):
        ctl.start(NAMES, points, 0.0, [0.2] * 4)
    assert ctl.outcome == Outcome.IDLE


def test_unknown_joint_is_an_invalid_joints_rejection() -> None:
    with pytest.raises(GoalRejected, match=r"unknown joint 'shoulder'") as info:
        make().validate(["j0", "shoulder"], [TrajectoryPoint(1.0, (0.2, 0.2))])
    assert info.value.invalid_joints


def test_path_tolerance_violation_aborts_naming_the_joint() -> None:
    ctl = make()
    pos = [0.2] * 4
    ctl.start(NAMES, [TrajectoryPoint(4.0, (0.3,) * 4)], 0.0, pos)
    step, _, _ = simulate(ctl, pos, stuck=(2,))  # motor 2 does not move (jammed)
    assert step.outcome == Outcome.PATH_TOLERANCE_VIOLATED
    assert "joint j2" in step.message and "path tolerance 0.02" in step.message
    assert step.commands == [0, 0, 0, 0]
    assert ctl.update(10.0, pos).commands == [0, 0, 0, 0]


def test_goal_tolerance_violation_after_goal_time_tolerance() -> None:
    ctl = make()
    pos = [0.2] * 4
    ctl.start(
        NAMES,
        [TrajectoryPoint(2.0, (0.21,) * 4)],
        0.0,
        pos,
        path_tolerance={n: -1.0 for n in NAMES},  # negative: no path limit
        goal_tolerance={"j1": 0.0001},
        goal_time_tolerance=0.5,
    )
    # the plant moves at a tenth of the commanded speed: j1 cannot settle within 0.1 mm in time
    step, _, _ = simulate(ctl, pos, speed_factor=0.1)
    assert step.outcome == Outcome.GOAL_TOLERANCE_VIOLATED
    assert "goal tolerance" in step.message and "joint j" in step.message


def test_a_new_goal_replaces_the_old_one() -> None:
    ctl = make()
    pos = [0.2] * 4
    ctl.start(NAMES, [TrajectoryPoint(4.0, (0.3,) * 4)], 0.0, pos)
    ctl.update(1.0, pos)
    ctl.start(NAMES, [TrajectoryPoint(4.0, (0.1,) * 4)], 1.0, pos)
    step = ctl.update(2.0, [0.2 - 0.025] * 4)
    assert all(c < 0 for c in step.commands)
    step, pos, _ = simulate(ctl, [0.2 - 0.025] * 4, t0=2.0)
    assert step.outcome == Outcome.SUCCEEDED and pos[0] == pytest.approx(0.1, abs=0.002)


def test_commands_never_exceed_the_joint_speed_limit() -> None:
    ctl = make()
    pos = [0.2] * 4
    ctl.start(NAMES, [TrajectoryPoint(2.0, (0.3,) * 4)], 0.0, pos, path_tolerance={n: -1 for n in NAMES})
    _, _, seen = simulate(ctl, pos)
    assert max(abs(c) for cmds in seen for c in cmds) <= 0.05 * CPM
