"""The planning scene file and the world built from it and a mission."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from tlt_ars.planning.collision_scene import Box, Capsule
from tlt_ars.planning.world import (
    DEFAULT_SCENE,
    build_scene,
    carried_capsules,
    load_scene_config,
    scene_config_from_dict,
    static_shapes,
    tower_origin,
    tower_shapes,
)
from tlt_common.config_schema import ConfigError, load_yaml
from tlt_common.mission import generate
from tlt_common.mission.schema import parse_mission


@pytest.fixture(scope="module")
def cfg():
    return load_scene_config()


@pytest.fixture(scope="module")
def mission():
    return parse_mission(generate.build("two_bay_test", 2), "<test>")


def test_scene_file_loads_and_homes_are_collision_free(cfg, mission):
    assert cfg.arm_names == ["ars_x", "ars_y"]
    for arm in cfg.arm_names:
        scene = build_scene(cfg, arm, mission)
        assert scene.first_collision(cfg.home(arm)) is None


def test_unknown_key_is_named():
    raw = load_yaml(DEFAULT_SCENE)
    raw["lifter"]["post_colour"] = "red"
    with pytest.raises(ConfigError) as err:
        scene_config_from_dict(raw, "scene.yaml")
    assert err.value.key == "lifter.post_colour"


@pytest.mark.parametrize(
    ("path", "value", "key"),
    [
        (("link_radii",), [0.1, 0.1], "link_radii"),
        (("arms", "ars_x", "home"), [0.0, -1.57, 9.0, 0.0, 0.0, 0.0], "arms.ars_x.home[2]"),
        (("limits", "position_lower"), [7.0, -6.0, -3.0, -6.0, -6.0, -6.0], "limits.position_lower[0]"),
        (("planning", "check_resolution"), 0.0, "planning.check_resolution"),
        (("planning", "via_configurations"), [[0.0, -1.57, 1.57]], "planning.via_configurations[0]"),
        (
            ("dispensers", "cross_frame", "uprights", "section"),
            0.0,
            "dispensers.cross_frame.uprights.section",
        ),
    ],
)
def test_bad_values_are_refused_naming_the_key(path, value, key):
    raw = copy.deepcopy(load_yaml(DEFAULT_SCENE))
    node = raw
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    with pytest.raises(ConfigError) as err:
        scene_config_from_dict(raw, "scene.yaml")
    assert err.value.key == key


def test_static_world(cfg, mission):
    groups = static_shapes(cfg, mission)
    posts = [s for s in groups["lifter"] if s.name.startswith("lifter/post")]
    assert len(posts) == 4 and all(isinstance(p, Capsule) for p in posts)
    bodies = {s.name for s in groups["dispensers"] if "/upright_" not in s.name and "/tag_post" not in s.name}
    assert bodies == {f"dispenser/{n}" for n in mission.dispensers}
    posts = {s.name for s in groups["dispensers"] if s.name.endswith("/tag_post")}
    assert posts == {f"dispenser/{n}/tag_post" for n in mission.dispensers}
    assert all(isinstance(s, Box) for s in groups["dispensers"])
    # Part racks (not rivet feeders) have four uprights, rising above the top part of the stack.
    for name, disp in mission.dispensers.items():
        uprights = [s for s in groups["dispensers"] if s.name.startswith(f"dispenser/{name}/upright_")]
        assert len(uprights) == (0 if disp.part_kind == "rivet" else 4), name
        racks = cfg.raw["dispensers"]
        top = racks["first_slot_height"] + (disp.count - 1) * racks["slot_pitch"]
        assert all(u.pose[2, 3] + u.size[2] / 2 > disp.position[2] + top for u in uprights), name
    assert {"floor", "ars_x/pedestal", "ars_y/pedestal"} <= {s.name for s in groups["environment"]}


def test_tower_grows_with_placed_members_and_rises_with_each_bay(cfg, mission):
    empty = tower_shapes(cfg, mission, [], bay=1)
    assert [s.name for s in empty if not s.name.startswith("tower/payload")] == []
    bay1 = [m.id for m in mission.bay_members(1)]
    built = tower_shapes(cfg, mission, bay1, bay=1)
    # 4 sides of the cross frame, one capsule per strut.
    assert len(built) - len(empty) == 4 + len(bay1) - 1
    assert tower_origin(cfg, mission, 2)[2] - tower_origin(cfg, mission, 1)[2] == pytest.approx(
        mission.bay_height
    )
    # The bottom cross frame of the bay under construction is at the build level.
    cross = [s for s in built if s.name.startswith("tower/bay1/cross_frame")]
    assert all(s.p0[2] == pytest.approx(cfg.raw["site"]["build_level"]) for s in cross)


def test_carried_parts_are_shortened_at_their_ends(cfg, mission):
    (strut,) = carried_capsules(cfg, mission, "vertical")
    length = np.linalg.norm(np.subtract(strut.p1, strut.p0))
    assert length == pytest.approx(mission.strut_lengths["vertical"] - 2 * cfg.raw["tower"]["end_clearance"])
    assert len(carried_capsules(cfg, mission, "cross_frame")) == 4
    assert carried_capsules(cfg, mission, "rivet") == []


def test_other_arm_moves_into_the_scene(cfg, mission):
    scene = build_scene(cfg, "ars_x", mission)
    names = {s.name for s in scene.group("other_arm")}
    assert "other_arm/link_3" in names and "other_arm/ee" in names


def test_base_joint_range_narrows_the_base_limits(cfg):
    kin = cfg.kinematics("ars_x")
    assert kin.lower[0] == pytest.approx(cfg.arm("ars_x")["base_joint_range"][0])
    assert kin.upper[0] == pytest.approx(cfg.arm("ars_x")["base_joint_range"][1])
    assert kin.upper[1] == pytest.approx(cfg.limits["position_upper"][1])
    raw = copy.deepcopy(load_yaml(DEFAULT_SCENE))
    raw["arms"]["ars_x"]["base_joint_range"] = [0.5, 1.0]  # home (0) outside it
    with pytest.raises(ConfigError) as err:
        scene_config_from_dict(raw, "scene.yaml")
    assert err.value.key == "arms.ars_x.home[0]"
    raw["arms"]["ars_x"]["base_joint_range"] = [1.0, -1.0]
    with pytest.raises(ConfigError) as err:
        scene_config_from_dict(raw, "scene.yaml")
    assert err.value.key == "arms.ars_x.base_joint_range"


def test_a_moving_width_stretches_each_box_on_the_slide_over_its_sweep(cfg):
    """Planned while the width slide moves, the end effector's boxes on the slide cover every
    width between the two ends, and the boxes off the slide stay where they are."""
    at = {w: {n: (p, np.asarray(s)) for n, p, s in cfg.ee_boxes(w)} for w in (0.05, 0.25)}
    swept = {n: (p, np.asarray(s)) for n, p, s in cfg.ee_boxes((0.25, 0.05))}
    on_slide = {b["name"] for b in cfg.raw["end_effector"]["boxes"] if b["on_width_slide"]}
    assert on_slide and set(swept) - on_slide
    for name, (pose, size) in swept.items():
        lo, hi = (pose[:3, 3] - size / 2, pose[:3, 3] + size / 2)
        for w in (0.05, 0.25):
            p, s = at[w][name]
            assert np.all(lo <= p[:3, 3] - s / 2 + 1e-12) and np.all(p[:3, 3] + s / 2 <= hi + 1e-12)
        if name in on_slide:
            assert size[0] == pytest.approx(at[0.05][name][1][0] + 0.2)
        else:
            assert np.allclose(size, at[0.05][name][1]) and np.allclose(pose, at[0.05][name][0])
