"""The twin's judgement of a placement (tlt_sim.model.placement) on hand-computed cases."""

from pathlib import Path

import numpy as np
import pytest
from tlt_sim.model.placement import placement_of, rotation_angle

from tlt_common.mission.schema import load_mission

MISSION = load_mission(Path(__file__).resolve().parents[3] / "missions" / "one_bay.yaml")
ORIGIN = np.array([1.0, 2.0, 0.5])


def _world(joint: str) -> np.ndarray:
    return ORIGIN + np.asarray(MISSION.joints[joint], dtype=float)


def _ends(member_id: str) -> np.ndarray:
    return np.array([_world(j) for j, _ in MISSION.member(member_id).joints])


def test_a_strut_is_matched_to_its_member_whichever_way_round_it_lies():
    ends = _ends("bay1/vertical/x1_y0")[::-1] + np.array([0.003, 0.0, 0.0])
    p = placement_of("v/0", "vertical", ends, MISSION, _world)
    assert p.member == "bay1/vertical/x1_y0"
    assert p.position_error == pytest.approx(0.003) and p.angle_error == pytest.approx(0.0, abs=1e-9)
    assert p.point_errors == pytest.approx((0.003, 0.003))


def test_a_tilted_strut_has_its_centre_and_angle_error():
    ends = _ends("bay1/vertical/x0_y0")
    length = float(np.linalg.norm(ends[1] - ends[0]))
    tilted = ends + np.array([[0.0, 0.0, 0.0], [0.004, 0.0, 0.0]])
    p = placement_of("v/1", "vertical", tilted, MISSION, _world)
    assert p.member == "bay1/vertical/x0_y0"
    assert p.position_error == pytest.approx(0.002)
    assert p.angle_error == pytest.approx(np.arctan2(0.004, length), rel=1e-3)
    assert p.within(0.005, 0.035) and not p.within(0.001, 0.035)


def test_a_cross_frame_turned_about_its_centre():
    corners = _ends("bay1/cross_frame")
    centre = corners.mean(0)
    a = 0.02
    turn = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    p = placement_of("cf/0", "cross_frame", (corners - centre) @ turn.T + centre, MISSION, _world)
    assert p.member == "bay1/cross_frame"
    assert p.position_error == pytest.approx(0.0, abs=1e-9) and p.angle_error == pytest.approx(a)
    assert rotation_angle(corners, corners) == pytest.approx(0.0, abs=1e-7)


def test_a_part_far_from_every_place_of_its_kind_is_at_none():
    raised = _ends("bay1/diagonal/face_x0") + np.array([0.0, 0.0, 2.0])
    p = placement_of("d/0", "diagonal", raised, MISSION, _world)
    assert p.member is None and p.position_error > 1.0 and p.point_errors == ()
    assert placement_of("x/0", "no_such_kind", _ends("bay1/cross_frame"), MISSION, _world).member is None
