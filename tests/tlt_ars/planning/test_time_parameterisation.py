"""Time parameterisation of joint paths under velocity and acceleration limits: the trapezoid per
segment (stops at every waypoint) and the reachability-analysis timing of blended paths."""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest

from tlt_ars.planning.blended_path import BlendedPath, Line, blend_corners
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
    wps = traj.stops()
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


def random_path(rng: np.random.Generator) -> list[np.ndarray]:
    """2 to 7 waypoints, segments of random direction and length (some short, some sharp turns)."""
    path = [rng.uniform(-2.0, 2.0, 6)]
    for _ in range(int(rng.integers(1, 7))):
        step = rng.normal(0.0, 1.0, 6) * rng.choice([0.02, 0.2, 0.8])
        if rng.random() < 0.2:
            step = -0.7 * (path[-1] - path[-2]) if len(path) > 1 else step  # a near reversal
        path.append(path[-1] + step)
    return path


def within_limits(traj, vel=VEL, acc=ACC, times=None) -> tuple[float, float]:
    """The largest |qd| / v and |qdd| / a over samples every 10 ms and at ``times``."""
    points = traj.points(0.01) + [traj.sample(t) for t in (times if times is not None else [])]
    v = max(float(np.max(np.abs(p.qd) / np.asarray(vel))) for p in points)
    a = max(float(np.max(np.abs(p.qdd) / np.asarray(acc))) for p in points)
    return v, a


def distance_to_polyline(q: np.ndarray, path: list[np.ndarray]) -> float:
    best = math.inf
    for a, b in pairwise(path):
        ab = b - a
        u = 0.0 if not ab.any() else float(np.clip((q - a) @ ab / (ab @ ab), 0.0, 1.0))
        best = min(best, float(np.linalg.norm(q - (a + u * ab))))
    return best


def test_blended_paths_keep_every_joint_within_its_limits_at_every_sample():
    rng = np.random.default_rng(67)
    for _ in range(40):
        path = random_path(rng)
        deviation = float(rng.choice([0.01, 0.05, 0.2]))
        blended = blend_corners(path, deviation)
        traj = time_parameterise(blended, VEL, ACC)
        v, a = within_limits(traj, times=rng.uniform(0.0, traj.duration, 100))
        assert v <= 1 + 1e-9 and a <= 1 + 1e-9
        points = traj.points(0.01)
        assert np.allclose(points[0].q, path[0]) and np.allclose(points[-1].q, path[-1])
        assert np.allclose(points[0].qd, 0) and np.allclose(points[-1].qd, 0, atol=1e-9)
        for p0, p1 in pairwise(points):
            dt = p1.t - p0.t
            if dt > 1e-6:
                # Positions move as the velocities say (no jump), within the limits.
                assert np.all(np.abs((p1.q - p0.q) / dt) <= np.asarray(VEL) * (1 + 1e-6))
                assert np.allclose((p1.q - p0.q) / dt, (p0.qd + p1.qd) / 2, atol=ACC[0] * dt)
            # The arm stays within the deviation of the planned polyline.
            assert distance_to_polyline(p1.q, path) <= deviation + 1e-9


def test_blending_is_never_slower_than_stopping_and_is_faster_round_corners():
    rng = np.random.default_rng(11)
    gained = 0
    for _ in range(40):
        path = random_path(rng)
        stops = time_parameterise(path, VEL, ACC).duration
        blended = time_parameterise(blend_corners(path, 0.05), VEL, ACC).duration
        assert blended <= stops
        gained += blended < 0.98 * stops
    assert gained >= 20


def test_the_reachability_timing_of_a_straight_line_matches_the_trapezoid():
    # Two collinear pieces make one section timed on the grid, not in closed form.
    for length in (0.05, 0.5, 1.0, 3.0):
        d = np.array([1.0, -2.0, 0.5, 0.0, 1.0, 3.0])
        d /= np.linalg.norm(d)
        pieces = [Line(np.zeros(6), d, length / 2), Line(d * length / 2, d, length / 2)]
        path = BlendedPath([pieces], [[np.zeros(6), d * length]])
        exact = straight_line_duration(np.zeros(6), d * length, VEL, ACC)
        assert time_parameterise(path, VEL, ACC).duration == pytest.approx(exact, rel=1e-3)


def test_a_corner_of_nearly_straight_segments_is_turned_at_full_speed():
    # The 2 cm waypoints of a Cartesian move: nearly collinear, a stop at each cost 1.4x and more.
    t = np.linspace(0.0, 1.0, 41)
    path = [np.array([1.2 * s, -0.4 * s + 0.05 * math.sin(3 * s), 0.6 * s, 0.0, 0.1 * s * s, 0.0]) for s in t]
    stops = time_parameterise(path, VEL, ACC).duration
    blended = time_parameterise(blend_corners(path, 0.005), VEL, ACC).duration
    straight = straight_line_duration(path[0], path[-1], VEL, ACC)
    assert stops > 3 * straight
    assert blended < 1.05 * straight


def test_points_are_at_least_a_microsecond_apart_even_where_a_stop_falls_beside_a_sample():
    # Segments whose durations put a stop within a nanosecond of the 50 ms grid.
    q1 = np.array([0.0, 0.0, 6.0 * 0.025**2, 0.0, 0.0, 0.0])  # a 0.05 s triangle on the elbow
    path = [np.zeros(6), q1 * (1 + 1e-9), q1 * 2]
    traj = time_parameterise(path, VEL, ACC)
    stops = [p.t for p in traj.stops()]
    assert any(abs(t / 0.05 - round(t / 0.05)) * 0.05 < 1e-6 for t in stops[1:-1])
    times = [p.t for p in traj.points(0.05)]
    assert all(b - a >= 1e-6 for a, b in pairwise(times))
    assert set(stops) <= set(times)


def test_a_section_the_grid_cannot_time_is_followed_with_its_stops(monkeypatch):
    from tlt_ars.planning import time_parameterisation

    path = [np.zeros(6), np.array([1.0, 0, 0, 0, 0, 0]), np.array([1.0, 1.0, 0, 0, 0, 0])]
    blended = blend_corners(path, 0.1)
    assert time_parameterise(blended, VEL, ACC).duration < time_parameterise(path, VEL, ACC).duration
    # One grid interval round a quarter turn: the arc's limits cannot be kept between its ends.
    monkeypatch.setattr(time_parameterisation, "ARC_GRID_TURN", 10.0)
    monkeypatch.setattr(time_parameterisation, "GRID_STEP", 10.0)
    monkeypatch.setattr(time_parameterisation, "PIECE_INTERVALS", 1)
    traj = time_parameterise(blended, VEL, ACC)
    assert traj.duration == pytest.approx(time_parameterise(path, VEL, ACC).duration)
    assert len(traj.stops()) == 3
    check_limits(traj, path)
