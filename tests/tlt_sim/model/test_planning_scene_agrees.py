"""The twin and the motion planner describe one machine: the lifter posts, the arm bases and the
dispenser racks' uprights the arms plan around (config/planning/scene.yaml) are where the twin
builds them (config/twin/edu.yaml, tlt_sim.model.generate). A difference puts every grasp and
placement off by it, or lets a planned path run the end effector into something."""

from __future__ import annotations

import itertools

import mujoco
import numpy as np
import pytest
from tlt_sim.model import names

from tlt_ars.planning.targets import rivet_pickup_point
from tlt_ars.planning.world import (
    dispenser_shapes,
    load_scene_config,
    rack_upright_height,
    rack_upright_positions,
)


def test_posts_and_arm_bases_agree(scene):
    planning = load_scene_config()
    twin_posts = np.array([np.asarray(p)[:2] for p in scene.info.post_xy])
    assert np.allclose(twin_posts, np.array(planning.raw["lifter"]["posts"]), atol=1e-3)
    for arm in names.ARMS:
        twin_arm, plan_arm = scene.edu["arms"][arm], planning.raw["arms"][arm]
        assert twin_arm["base"] == pytest.approx(plan_arm["base"])
        assert twin_arm["yaw_deg"] == pytest.approx(plan_arm["yaw_deg"])
        assert twin_arm["pedestal_height"] == pytest.approx(plan_arm["pedestal_height"])


def test_dispenser_rack_uprights_agree(scene):
    """The planner keeps the end effector off the rack uprights the twin builds (same place, same
    height): uprights it did not know of stopped the arm short of the parts below the top one."""
    planning = load_scene_config()
    m, d = scene.model, scene.data
    checked = 0
    for name, disp in scene.mission.dispensers.items():
        if disp.part_kind == "rivet":
            continue
        body = m.body(f"dispenser/{name}")
        origin, rot = d.xpos[body.id], d.xmat[body.id].reshape(3, 3)
        twin = []
        for g in range(m.ngeom):
            if m.geom_bodyid[g] == body.id and "/upright_" in m.geom(g).name:
                x, y, _ = rot.T @ (d.geom_xpos[g] - origin)
                twin.append((round(float(x), 4), round(float(y), 4), 2 * float(m.geom_size[g][2])))
        centres = rack_upright_positions(planning, scene.mission, disp)
        planned = [(round(float(x), 4), round(float(y), 4)) for x, y in centres]
        assert sorted(t[:2] for t in twin) == sorted(planned), name
        assert all(t[2] == pytest.approx(rack_upright_height(planning, disp)) for t in twin), name
        checked += 1
    assert checked >= 3


def test_rivet_feeders_agree(scene):
    """A gun sent to the planner's pickup point takes a rivet in the twin, and the planner's box
    covers the twin's feeder (a pickup point 35 cm down inside the column loaded no rivet at all)."""
    planning = load_scene_config()
    m, d = scene.model, scene.data
    boxes = {s.name: s for s in dispenser_shapes(planning, scene.mission)}
    feeders = [n for n, disp in scene.mission.dispensers.items() if disp.part_kind == "rivet"]
    assert feeders
    for name in feeders:
        pickup = scene.site_position(f"dispenser/{name}/pickup")
        planned = rivet_pickup_point(planning, scene.mission.dispensers[name])
        assert np.linalg.norm(planned - pickup) < 0.01, name
        box = boxes[f"dispenser/{name}"]
        box_top = box.pose[2, 3] + box.size[2] / 2
        column, tray = m.geom(f"dispenser/{name}/column"), m.geom(f"dispenser/{name}/box")
        assert d.geom_xpos[column.id][2] + column.size[1] <= box_top + 1e-6, name  # half-length
        assert d.geom_xpos[tray.id][2] + tray.size[2] == pytest.approx(box_top, abs=1e-6), name


# Twin geom (after "<arm>/") -> the planner's box that must hold it. The jaws and the fixed fingers
# are left out on both sides: they close on the part.
EE_BOXES = {
    "ee/hub": "hub",
    "ee/bar": "bar",
    **{f"gripper_{s}/body": f"gripper_{s}" for s in "ab"},
    **{f"rivet_gun_{s}/body": f"rivet_gun_{s}" for s in "ab"},
    **{f"rivet_gun_{s}/bracket": f"gun_bracket_{s}" for s in "ab"},
    **{f"d405_{s}/housing": f"d405_{s}" for s in "ab"},
}


@pytest.mark.parametrize("width", [0.0, 0.25])
def test_every_part_of_the_end_effector_lies_in_its_planner_box_at_any_width(scene, width):
    """The planner's end-effector boxes hold the twin's geoms, on the width slide too (a diagonal
    is carried at 0.25 m, gun 1 passing a lifter post by centimetres). A gun bracket the planner
    did not know of ran into a dispenser's tag post and overloaded the width servo."""
    planning = load_scene_config()
    boxes = {name: (pose, np.asarray(size)) for name, pose, size in planning.ee_boxes(width)}
    m, d = scene.model, scene.data
    for arm in names.ARMS:
        scene.set_joint_state(names.width_joint(arm), width)
        flange_pos, flange_rot = scene.body_pose(names.ee_body(arm))
        for twin_name, planned in EE_BOXES.items():
            geom = m.geom(f"{arm}/{twin_name}")
            half = np.asarray(m.geom_size[geom.id])
            if m.geom_type[geom.id] == mujoco.mjtGeom.mjGEOM_CYLINDER:  # radius, half length
                half = np.array([half[0], half[0], half[1]])
            rot = flange_rot.T @ d.geom_xmat[geom.id].reshape(3, 3)
            centre = flange_rot.T @ (d.geom_xpos[geom.id] - flange_pos)
            corners = [centre + rot @ (half * np.array(c)) for c in itertools.product((-1, 1), repeat=3)]
            pose, size = boxes[planned]
            inside = [np.abs(pose[:3, :3].T @ (c - pose[:3, 3])) <= size / 2 + 1e-3 for c in corners]
            assert np.all(inside), (arm, twin_name, planned, centre, half)


def test_every_dispensers_tag_post_is_in_the_planners_scene(scene):
    """The planner keeps the arm off each dispenser's AprilTag post, where the twin builds it: a
    path that did not know of it ran an end effector into the vertical rack's post."""
    shapes = {s.name: s for s in dispenser_shapes(load_scene_config(), scene.mission)}
    m, d = scene.model, scene.data
    for name in scene.mission.dispensers:
        geom = m.geom(f"dispenser/{name}/tag_post")
        box = shapes[f"dispenser/{name}/tag_post"]
        assert box.pose[:3, 3] == pytest.approx(d.geom_xpos[geom.id], abs=1e-3), name
        assert np.asarray(box.size) == pytest.approx(2 * m.geom_size[geom.id], abs=1e-3), name
