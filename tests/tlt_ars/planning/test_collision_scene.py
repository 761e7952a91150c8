"""Collision checks of one arm on hand-built scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tlt_ars.planning.collision_scene import Capsule, CollisionScene, arm_link_segments, box_at
from tlt_common.geometry.transforms import pose_matrix
from tlt_common.geometry.ur10e import Ur10eKinematics

HOME = np.array([0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])
EE = [("bar", pose_matrix([0.0, 0.0, 0.06]), (0.7, 0.06, 0.04))]


def make_scene(**kw) -> CollisionScene:
    kin = Ur10eKinematics(base=pose_matrix([0.0, 0.0, 0.5]), tool=pose_matrix([0.0, 0.0, 0.16]))
    return CollisionScene(kin, ee_boxes=EE, padding=0.01, name="arm", **kw)


def forearm_midpoint(scene: CollisionScene, q: np.ndarray) -> np.ndarray:
    p0, p1 = arm_link_segments(scene.kin, q)[2]
    return (p0 + p1) / 2


def test_free_pose_in_an_empty_world():
    scene = make_scene()
    assert not scene.in_collision(HOME)
    assert scene.first_collision(HOME) is None


def test_arm_through_a_lifter_post_collides_and_names_it():
    scene = make_scene()
    x, y, _ = forearm_midpoint(scene, HOME)
    scene.set_group("lifter", [Capsule("lifter/post_0", (x, y, 0.0), (x, y, 2.0), 0.035)])
    assert scene.in_collision(HOME)
    assert scene.first_collision(HOME) == ("arm/link_3", "lifter/post_0")
    # Turning the base a quarter turn takes the forearm away from the post.
    turned = HOME.copy()
    turned[0] += math.pi / 2
    assert not scene.in_collision(turned)


def test_post_just_outside_the_padding_is_clear():
    scene = make_scene()
    p0, p1 = arm_link_segments(scene.kin, HOME)[2]
    mid = (p0 + p1) / 2
    # A vertical post beside the horizontal forearm, offset sideways (perpendicular to the forearm).
    along = (p1 - p0) / np.linalg.norm(p1 - p0)
    side = np.cross(along, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    clear = scene.link_radii[2] + 0.035 + 2 * scene.padding + 0.005
    for offset, hits in ((clear, False), (clear - 0.01, True)):
        c = mid + side * offset
        scene.set_group("lifter", [Capsule("post", (c[0], c[1], 0.0), (c[0], c[1], 2.0), 0.035)])
        assert scene.in_collision(HOME) is hits


def test_box_obstacle_and_floor():
    scene = make_scene()
    flange = (scene.kin.base @ scene.kin.flange(HOME))[:3, 3]
    scene.set_group("dispensers", [box_at("dispenser/a", flange, (0.1, 0.1, 0.1))])
    assert scene.first_collision(HOME)[1] == "dispenser/a"
    scene.set_group("dispensers", [])
    scene.set_group("environment", [box_at("floor", (0, 0, -0.05), (10, 10, 0.1))])
    assert not scene.in_collision(HOME)
    down = np.array([0.0, 0.3, 1.2, 0.0, -math.pi / 2, 0.0])  # reaching under the floor
    assert scene.first_collision(down)[1] == "floor"


def test_carried_part_moves_with_the_tool():
    scene = make_scene()
    tool = scene.kin.forward(HOME)
    # An obstacle 0.45 m along the tool x, past the end effector bar: only a carried strut reaches it.
    p = (tool @ np.array([0.45, 0.0, 0.0, 1.0]))[:3]
    scene.set_group(
        "tower",
        [Capsule("tower/m", tuple(p - np.array([0, 0, 0.2])), tuple(p + np.array([0, 0, 0.2])), 0.02)],
    )
    assert not scene.in_collision(HOME)
    scene.attach([Capsule("vertical", (-0.5, 0.0, 0.0), (0.5, 0.0, 0.0), 0.02)])
    assert scene.first_collision(HOME) == ("carried/vertical", "tower/m")
    scene.detach()
    assert not scene.in_collision(HOME)


def test_contact_groups_let_the_end_effector_touch_but_not_the_links():
    plain = make_scene()
    bar_end = (plain.kin.base @ plain.kin.flange(HOME) @ np.array([0.3, 0.0, 0.06, 1.0]))[:3]
    touching = [box_at("tower/joint", bar_end, (0.06, 0.06, 0.06))]
    plain.set_group("tower", touching)
    assert plain.first_collision(HOME) == ("arm/ee/bar", "tower/joint")
    scene = make_scene(contact_groups=("tower",))
    scene.set_group("tower", touching)
    assert not scene.in_collision(HOME)
    x, y, z = forearm_midpoint(scene, HOME)
    scene.set_group("tower", [box_at("tower/joint", (x, y, z), (0.1, 0.1, 0.1))])
    assert scene.first_collision(HOME) == ("arm/link_3", "tower/joint")


def test_allowed_pairs_are_not_tested():
    scene = make_scene(allowed=[("link_1", "pedestal")])
    scene.set_group("environment", [box_at("pedestal", (0, 0, 0.25), (0.2, 0.2, 0.5))])
    assert not scene.in_collision(HOME)


def test_self_collision_of_a_folded_arm():
    scene = make_scene()
    folded = np.array([0.0, -math.pi / 2, 3.0, -1.5, -1.5, 0.0])  # forearm folded onto the upper arm
    hit = scene.first_collision(folded)
    assert hit is not None and hit[0].startswith("arm/") and hit[1].startswith("arm/")


def test_other_arm_is_an_obstacle():
    scene = make_scene()
    other = Ur10eKinematics(base=scene.kin.base, tool=scene.kin.tool)
    scene.set_other_arm(other, HOME)
    assert scene.first_collision(HOME)[1].startswith("other_arm/")
    scene.set_group("other_arm", [])
    assert not scene.in_collision(HOME)


def test_broad_phase_gives_the_same_answers_as_every_pair():
    scene = make_scene()
    scene.set_group("environment", [box_at("floor", (0, 0, -0.05), (10, 10, 0.1))])
    scene.set_group(
        "lifter",
        [
            Capsule(f"post_{i}", (x, y, 0.0), (x, y, 2.0), 0.035)
            for i, (x, y) in enumerate([(0.4, 0.4), (-0.5, 0.3)])
        ],
    )
    rng = np.random.default_rng(5)
    qs = rng.uniform(-math.pi, math.pi, (400, 6))
    broad = [scene.in_collision(q) for q in qs]
    every = [scene.in_collision_all_pairs(q) for q in qs]
    assert broad == every
    assert 0 < sum(broad) < len(broad)


def test_segment_check_finds_a_collision_between_free_ends():
    scene = make_scene()
    turned = HOME.copy()
    turned[0] += 1.0
    mid = HOME.copy()
    mid[0] += 0.5
    x, y, _ = forearm_midpoint(scene, mid)
    scene.set_group("lifter", [Capsule("post", (x, y, 0.0), (x, y, 2.0), 0.03)])
    assert not scene.in_collision(HOME) and not scene.in_collision(turned)
    bad = scene.segment_collision(HOME, turned, 0.01)
    assert bad is not None and scene.in_collision(bad)
    assert not scene.segment_free(HOME, turned, 0.01)


def test_wrong_link_radii_are_refused():
    with pytest.raises(ValueError, match="six link radii"):
        CollisionScene(Ur10eKinematics(), link_radii=(0.1, 0.1))
