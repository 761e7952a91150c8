"""Blending a planned joint path's corners: arcs tangent to both segments, within the deviation,
checked by the collision test, and stops where a blend is refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tlt_ars.planning.blended_path import MAX_BLEND_TURN, Arc, Line, blend_corners

SQUARE = [np.zeros(6), np.array([1.0, 0, 0, 0, 0, 0]), np.array([1.0, 1.0, 0, 0, 0, 0])]


def pieces(path):
    return [p for section in path.sections for p in section]


def test_a_right_angle_is_cut_by_an_arc_tangent_to_both_segments_within_the_deviation():
    path = blend_corners(SQUARE, 0.05)
    assert path.blended == 1 and path.stops == 0 and len(path.sections) == 1
    first, arc, last = pieces(path)
    assert isinstance(first, Line) and isinstance(arc, Arc) and isinstance(last, Line)
    assert arc.deviation() == pytest.approx(0.05)
    assert arc.angle == pytest.approx(math.pi / 2)
    # Continuous position and tangent where the pieces meet.
    for a, b in ((first, arc), (arc, last)):
        qa, dqa, _ = a.evaluate(np.array([a.length]))
        qb, dqb, _ = b.evaluate(np.array([0.0]))
        assert np.allclose(qa, qb) and np.allclose(dqa, dqb)
    q_end, _, _ = last.evaluate(np.array([last.length]))
    assert np.allclose(q_end[0], SQUARE[-1])
    # The middle of the arc is the deviation from the corner; the curvature is 1 / radius.
    q_mid, dq_mid, ddq_mid = arc.evaluate(np.array([arc.length / 2]))
    assert np.linalg.norm(q_mid[0] - SQUARE[1]) == pytest.approx(0.05)
    assert np.linalg.norm(dq_mid[0]) == pytest.approx(1.0)
    assert np.linalg.norm(ddq_mid[0]) == pytest.approx(1.0 / arc.radius)


def test_an_arc_takes_at_most_half_of_each_segment():
    short = [np.zeros(6), np.array([0.1, 0, 0, 0, 0, 0]), np.array([0.1, 2.0, 0, 0, 0, 0])]
    path = blend_corners(short, 1.0)
    arc = next(p for p in pieces(path) if isinstance(p, Arc))
    assert arc.radius * math.tan(arc.angle / 2) == pytest.approx(0.05)
    assert path.length < 0.1 + 2.0


def test_a_blend_that_collides_is_tried_smaller_then_left_as_a_stop():
    corner = SQUARE[1]
    # An obstacle 0.03-0.07 from the corner, inside it: the full 0.05 blend is refused, a quarter
    # of it (0.0125 from the corner, cutting 0.03 of each segment) passes.
    path = blend_corners(
        SQUARE, 0.05, is_free=lambda q: not 0.03 < np.linalg.norm(q - corner) < 0.07 or _on_polyline(q)
    )
    arc = next(p for p in pieces(path) if isinstance(p, Arc))
    assert arc.deviation() == pytest.approx(0.0125)
    never = blend_corners(SQUARE, 0.05, is_free=lambda q: False)
    assert never.blended == 0 and never.stops == 1 and len(never.sections) == 2
    assert all(isinstance(p, Line) for p in pieces(never))


def _on_polyline(q: np.ndarray) -> bool:
    return bool((abs(q[1]) < 1e-9 and 0 <= q[0] <= 1) or (abs(q[0] - 1) < 1e-9 and 0 <= q[1] <= 1))


def test_a_near_reversal_is_a_stop_and_a_straight_continuation_is_neither():
    turn = MAX_BLEND_TURN + 0.05
    back = np.array([1.0 + math.cos(turn), math.sin(turn), 0, 0, 0, 0])
    path = blend_corners([SQUARE[0], SQUARE[1], back], 0.05)
    assert path.stops == 1 and path.blended == 0
    on = blend_corners([np.zeros(6), np.full(6, 0.5), np.ones(6)], 0.05)
    assert on.stops == 0 and on.blended == 0 and len(on.sections) == 1


def test_duplicate_waypoints_and_a_single_waypoint():
    path = blend_corners([SQUARE[0], SQUARE[0], SQUARE[1], SQUARE[1], SQUARE[2]], 0.05)
    assert path.blended == 1
    single = blend_corners([np.ones(6)], 0.05)
    assert single.length == 0.0 and np.allclose(single.start, 1.0)


@pytest.mark.parametrize(
    ("path", "match"),
    [([], "empty path"), ([np.zeros(6), np.zeros(5)], "same number"), ([np.full(6, math.nan)], "finite")],
)
def test_bad_paths_are_refused(path, match):
    with pytest.raises(ValueError, match=match):
        blend_corners(path, 0.05)
