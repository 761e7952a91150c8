"""Time parameterisation of joint paths under velocity and acceleration limits."""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest

from tlt_ars.planning.time_parameterisation import straight_line_duration, time_parameterise

VEL = [2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416]
ACC = [4.0, 4.0, 6.0, 6.0, 6.0, 6.0]


def check_limits(traj, path, vel=VEL, acc=ACC, period=0.002):
    points = traj.points(period)
    v = np.asarray(vel)
    a = np.asarray(acc)
    for p in points:
        assert np.all(np.abs(p.qd) <= v * (1 + 1e-9))
        assert np.all(np.abs(p.qdd) <= a * (1 + 1e-9))
    # Velocities are the derivative of the positions (finite differences between samples).
    for p0, p1 in pairwise(points):
        dt = p1.t - p0.t
        if dt > 1e-6:
            assert np.all(np.abs((p1.q - p0.q) / dt) <= v * (1 + 1e-6))
    assert np.allclose(points[0].q, path[0]) and np.allclose(points[-1].q, path[-1])
    assert np.allclose(points[0].qd, 0) and np.allclose(points[-1].qd, 0)
    assert points[-1].t == pytest.approx(traj.duration)


def test_trapezoid_duration_of_a_single_joint_move():
    # 2 rad on the base: accelerate to 2.0944 rad/s at 4 rad/s2 (0.5236 s, 0.5483 rad), cruise the
    # remaining 0.9034 rad at 2.0944 rad/s (0.4313 s), decelerate (0.5236 s): 1.4785 s.
    d = straight_line_duration(np.zeros(6), [2.0, 0, 0, 0, 0, 0], VEL, ACC)
    ta = 2.0944 / 4.0
    assert d == pytest.approx(2 * ta + (2.0 - 2.0944 * ta) / 2.0944, rel=1e-9)


def test_triangle_duration_of_a_short_move():
    # 0.2 rad never reaches full speed: t = 2 sqrt(d / a).
    d = straight_line_duration(np.zeros(6), [0, 0, 0.2, 0, 0, 0], VEL, ACC)
    assert d == pytest.approx(2 * math.sqrt(0.2 / 6.0), rel=1e-9)


def test_slowest_joint_sets_the_pace_and_joints_stay_synchronised():
    path = [np.zeros(6), np.array([1.0, 0.0, 3.0, 0.0, 0.0, 0.0])]
    traj = time_parameterise(path, VEL, ACC)
    assert traj.duration == pytest.approx(straight_line_duration(path[0], path[1], VEL, ACC))
    # Elbow (3 rad at 3.14 rad/s) is slower than the base (1 rad at 2.09 rad/s).
    assert traj.duration == pytest.approx(straight_line_duration(np.zeros(6), [0, 0, 3.0, 0, 0, 0], VEL, ACC))
    for p in traj.points(0.01):
        assert p.q[2] == pytest.approx(3.0 * p.q[0], abs=1e-9)  # on the straight line
    check_limits(traj, path)


def test_multi_segment_path_respects_limits_and_stops_at_waypoints():
    path = [
        np.zeros(6),
        np.array([1.0, -0.5, 0.3, 0.0, 0.2, 0.0]),
        np.array([-0.4, 0.5, 1.5, 1.0, 0.0, -2.0]),
    ]
    traj = time_parameterise(path, VEL, ACC)
    check_limits(traj, path)
    wps = traj.waypoints()
    assert len(wps) == 3
    for wp, q in zip(wps, path, strict=True):
        assert np.allclose(wp.q, q) and np.allclose(wp.qd, 0)
    total = sum(straight_line_duration(a, b, VEL, ACC) for a, b in pairwise(path))
    assert traj.duration == pytest.approx(total)


def test_single_point_and_zero_length_paths():
    q = np.ones(6)
    assert time_parameterise([q], VEL, ACC).duration == 0.0
    assert straight_line_duration(q, q, VEL, ACC) == 0.0
    traj = time_parameterise([q, q, q + 0.1], VEL, ACC)
    check_limits(traj, [q, q + 0.1])


@pytest.mark.parametrize(
    ("path", "vel", "acc", "match"),
    [
        ([], VEL, ACC, "empty path"),
        ([np.zeros(6), np.zeros(5)], VEL, ACC, "same number"),
        ([np.zeros(6), np.full(6, math.nan)], VEL, ACC, "finite"),
        ([np.zeros(6)], VEL[:5], ACC, "velocity and acceleration limits"),
        ([np.zeros(6)], VEL, [0.0] * 6, "positive"),
    ],
)
def test_bad_input_is_refused(path, vel, acc, match):
    with pytest.raises(ValueError, match=match):
        time_parameterise(path, vel, acc)
