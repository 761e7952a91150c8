"""Reachability of a mission's members, checked when it loads."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from tlt_ars.planning.reachability import UnreachableMember, check_mission_reach, require_reachable
from tlt_ars.planning.targets import placement_targets
from tlt_ars.planning.world import DEFAULT_SCENE, load_scene_config, scene_config_from_dict
from tlt_common.config_schema import load_yaml
from tlt_common.mission import generate
from tlt_common.mission.schema import load_mission, parse_mission

MISSIONS = Path(__file__).resolve().parents[3] / "missions"


@pytest.fixture(scope="module")
def cfg():
    return load_scene_config()


def test_one_bay_mission_is_reachable_by_the_assigned_arms(cfg):
    mission = load_mission(MISSIONS / "one_bay.yaml")
    report = require_reachable(cfg, mission)
    assert report.ok
    # Every member placed, every rivet set: far verticals need both arms (add and affix).
    far = [m for m in mission.members if m.group == "far_vertical"]
    for m in far:
        assert (m.id, m.add_ars, "place") in report.reached
        assert any(k[0] == m.id and k[1] == m.affix_ars and "affix" in k[2] for k in report.reached)
    for (_member, arm, _step), q in report.reached.items():
        kin = cfg.kinematics(arm)
        assert all(kin.lower <= q) and all(q <= kin.upper)


def test_wide_bays_put_members_out_of_reach(cfg):
    mission = parse_mission(generate.build("wide", 1, width=2.5, height=0.75), "<wide>")
    report = check_mission_reach(cfg, mission, arms=["ars_x"])
    assert not report.ok
    issue = next(i for i in report.issues if i.member == "bay1/vertical/x1_y0" and i.step == "place")
    assert issue.arm == "ars_x"
    with pytest.raises(UnreachableMember) as err:
        require_reachable(cfg, mission, arms=["ars_x"])
    assert "mission 'wide'" in str(err.value) and "unreachable step" in str(err.value)


def test_steps_of_an_arm_missing_from_the_scene_are_reported():
    raw = copy.deepcopy(load_yaml(DEFAULT_SCENE))
    del raw["arms"]["ars_y"]
    only_x = scene_config_from_dict(raw, "scene.yaml")
    mission = load_mission(MISSIONS / "one_bay.yaml")
    report = check_mission_reach(only_x, mission, arms=["ars_x", "ars_y"])
    missing = [i for i in report.issues if i.arm == "ars_y"]
    assert missing and all("no arm 'ars_y'" in i.reason for i in missing)
    assert all(i.arm == "ars_y" for i in report.issues)
    targets = placement_targets(only_x, mission, mission.members[0], "ars_x")
    assert targets and all(t.pose.shape == (4, 4) for t in targets)


def test_usable_approaches_and_same_branch(cfg):
    from tlt_ars.planning.reachability import TargetUnreachable, same_branch, usable_approaches
    from tlt_ars.planning.world import build_scene

    mission = load_mission(MISSIONS / "one_bay.yaml")
    member = mission.member("bay1/vertical/x0_y0")
    full = build_scene(cfg, "ars_x", mission, carrying="vertical")
    contact = build_scene(cfg, "ars_x", mission, carrying="vertical", contact=True)
    targets = placement_targets(cfg, mission, member, "ars_x")
    branches = []
    for t in targets:
        try:
            branches = usable_approaches(full, contact, t, cfg.home("ars_x"), 0.005)
        except TargetUnreachable:
            continue
        target = t
        break
    assert branches
    for q_pre, q in branches:
        assert not full.in_collision(q_pre) and not contact.in_collision(q)
        assert np.allclose(full.kin.forward(q_pre), target.pre_pose, atol=1e-6)
    accept = same_branch([q_pre for q_pre, _ in branches])
    q_pre = branches[0][0]
    turned = q_pre.copy()
    turned[0] -= 2 * np.pi
    assert accept(q_pre) and accept(turned)
    assert not accept(q_pre + 0.1)
