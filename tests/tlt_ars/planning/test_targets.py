"""Grasp and placement targets: where the tool goes, and which rivet gun that puts where."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tlt_ars.planning.targets import dispenser_targets, part_in_tool, placement_targets
from tlt_ars.planning.world import (
    GUN_OFFSET,
    carried_capsules,
    dispenser_frame,
    load_scene_config,
    tower_origin,
)
from tlt_common.mission.schema import load_mission

MISSION = load_mission(Path(__file__).resolve().parents[3] / "missions" / "one_bay.yaml")


def _gun_0(pose: np.ndarray) -> np.ndarray:
    # Rivet gun 0 sits GUN_OFFSET along tool -x (as rivet_targets puts it on a joint).
    return (pose @ np.array([-GUN_OFFSET, 0.0, 0.0, 1.0]))[:3]


@pytest.mark.parametrize(
    "member_id",
    ["bay1/vertical/x0_y0", "bay1/vertical/x1_y1", "bay1/vertical/x0_y1", "bay1/diagonal/face_x0",
     "bay1/diagonal/face_y1"],
)  # fmt: skip
def test_a_strut_is_placed_with_the_loaded_gun_on_its_add_joint(member_id):
    """The add rivet is loaded into gun 0: a vertical held the other way round riveted its other
    end, and the affix rivet then found that end taken. A diagonal, longer than the guns' span,
    is held off its middle to have gun 0 on its end."""
    cfg = load_scene_config()
    member = MISSION.member(member_id)
    origin = tower_origin(cfg, MISSION, member.bay)
    points = {name: origin + np.asarray(p, dtype=float) for name, p in member.joints}
    add = next(r.joint for r in member.rivets if r.step == "add")
    flipped = replace(member, rivets=tuple(replace(r, joint=next(j for j in points if j != r.joint))
                                           if r.step == "add" else r for r in member.rivets))  # fmt: skip
    for m, joint in ((member, add), (flipped, next(j for j in points if j != add))):
        targets = placement_targets(cfg, MISSION, m, m.add_ars)
        assert targets
        for t in targets:
            assert np.linalg.norm(_gun_0(t.pose) - points[joint]) < 1e-6, (m.id, joint, t.label)


def test_a_diagonal_is_held_the_same_way_from_its_grasp_to_its_placement():
    """The part sits in the tool where the dispenser grasp put it (jaws hold a tube where it lies
    along them): the grasp target has the stowed diagonal's middle at ``part_in_tool``, and so do
    the placement targets (the middle of its joints) and the planner's carried capsule."""
    cfg = load_scene_config()
    member = MISSION.member("bay1/diagonal/face_x0")
    in_tool = part_in_tool(MISSION, "diagonal")
    assert in_tool[0, 3] == pytest.approx(MISSION.strut_lengths["diagonal"] / 2 - GUN_OFFSET)
    disp = MISSION.dispensers[member.dispenser]
    frame = dispenser_frame(cfg, disp)
    for t in dispenser_targets(cfg, MISSION, member.dispenser, member.add_ars):
        middle = (t.pose @ in_tool)[:3, 3]
        # on the stowed part's axis (the dispenser's x), above its centre
        assert abs(float((middle - frame[:3, 3]) @ frame[:3, 0])) < 1e-9, t.label
    origin = tower_origin(cfg, MISSION, member.bay)
    joints = [origin + np.asarray(p, dtype=float) for _, p in member.joints]
    for t in placement_targets(cfg, MISSION, member, member.add_ars):
        assert np.linalg.norm((t.pose @ in_tool)[:3, 3] - (joints[0] + joints[1]) / 2) < 1e-9, t.label
    (capsule,) = carried_capsules(cfg, MISSION, "diagonal")
    assert (np.asarray(capsule.p0) + capsule.p1)[0] / 2 == pytest.approx(in_tool[0, 3])
