"""The twin and the motion planner describe one machine: the lifter posts and the arm bases the
arms plan around (config/planning/scene.yaml) are where the twin builds them (config/twin/edu.yaml).
A difference puts every grasp and placement off by it."""

from __future__ import annotations

import numpy as np
import pytest
from tlt_sim.model import names

from tlt_ars.planning.world import load_scene_config


def test_posts_and_arm_bases_agree(scene):
    planning = load_scene_config()
    twin_posts = np.array([np.asarray(p)[:2] for p in scene.info.post_xy])
    assert np.allclose(twin_posts, np.array(planning.raw["lifter"]["posts"]), atol=1e-3)
    for arm in names.ARMS:
        twin_arm, plan_arm = scene.edu["arms"][arm], planning.raw["arms"][arm]
        assert twin_arm["base"] == pytest.approx(plan_arm["base"])
        assert twin_arm["yaw_deg"] == pytest.approx(plan_arm["yaw_deg"])
        assert twin_arm["pedestal_height"] == pytest.approx(plan_arm["pedestal_height"])
