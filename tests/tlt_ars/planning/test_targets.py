"""Grasp and placement targets: where the tool goes, and which rivet gun that puts where."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tlt_ars.planning.targets import DEFAULT_GUN_OFFSET, placement_targets
from tlt_ars.planning.world import load_scene_config, tower_origin
from tlt_common.mission.schema import load_mission

MISSION = load_mission(Path(__file__).resolve().parents[3] / "missions" / "one_bay.yaml")


def _gun_0(pose: np.ndarray) -> np.ndarray:
    # Rivet gun 0 sits DEFAULT_GUN_OFFSET along tool -x (as rivet_targets puts it on a joint).
    return (pose @ np.array([-DEFAULT_GUN_OFFSET, 0.0, 0.0, 1.0]))[:3]


@pytest.mark.parametrize("member_id", ["bay1/vertical/x0_y0", "bay1/vertical/x1_y1", "bay1/vertical/x0_y1"])
def test_a_vertical_is_placed_with_the_loaded_gun_on_its_add_joint(member_id):
    """The add rivet is loaded into gun 0: a vertical held the other way round riveted its other
    end, and the affix rivet then found that end taken."""
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
