"""A cross frame the ARS lets go of at its place rests on the foundation pads, where it belongs.

The ARS releases the bottom cross frame of a bay before the CRS latches the Active Grippers on it
(paper §V.C.2, Fig. 21) and checks the placement with its EE camera in between, so a frame let go
of at the build level must stay there: each corner within the mission's position tolerance of its
joint, not on the floor. ARS X stands at the placement configuration its planner picks for
``bay1/cross_frame``; the frame is put on its grasp line, the jaws close on it and open again.
"""

import dataclasses

import mujoco
import numpy as np
import pytest
from tlt_sim.model import names

from tlt_ars.planning.reachability import reach_target
from tlt_ars.planning.targets import placement_targets
from tlt_ars.planning.world import build_scene, load_scene_config

CORNERS = ("x0_y0", "x1_y0", "x1_y1", "x0_y1")


def _placement(mission) -> np.ndarray:
    cfg = load_scene_config()
    kw = dict(placed=set(), bay=1, carrying="cross_frame")
    free = build_scene(cfg, "ars_x", mission, contact=False, **kw)
    contact = build_scene(cfg, "ars_x", mission, contact=True, **kw)
    target = placement_targets(cfg, mission, mission.member("bay1/cross_frame"), "ars_x")[0]
    _, q = reach_target(free, contact, target, cfg.home("ars_x"), cfg.planning["dense_check_resolution"])
    return q


def test_a_cross_frame_released_at_its_place_rests_on_the_pads(scene, mover):
    arm, part = "ars_x", scene.next_part("cross_frame_dispenser")
    for joint, value in zip(names.arm_joints(arm), _placement(scene.mission), strict=True):
        scene.set_joint_state(joint, float(value))
    mujoco.mj_forward(scene.model, scene.data)
    info = scene.part(part)
    joints = {c: scene.joint_position_world(f"bay1/{c}") for c in CORNERS}
    centre, axis = scene.assembly.grasp_line(arm)
    inward = sum(joints.values()) / len(joints) - centre
    inward -= (inward @ axis) * axis
    inward /= np.linalg.norm(inward)
    seat = np.column_stack([axis, inward, np.cross(axis, inward)])
    scene.place_part(part, centre - axis * info.length / 2, seat)
    m = mover(scene, arm)
    m.jaws(True)
    assert scene.holding(arm) == info.body
    m.jaws(False, settle_s=1.5)
    assert scene.holding(arm) is None and scene.part_state(part) == "dropped"
    seated = [scene.site_position(names.corner_site(info.body, i)) for i in range(4)]
    tolerance = scene.mission.inspection["position_tolerance"]
    for c, j in joints.items():
        assert min(np.linalg.norm(s - j) for s in seated) <= tolerance, (c, j, seated)


def test_the_release_is_recorded_with_where_the_frame_really_is(scene, mover):
    """What the twin logs of each release (Twin.tick): the part's truth against its place, in the
    mission's terms. Released at its place, the frame is bay1/cross_frame within the tolerances;
    held 8 mm along its side, 8 mm off; let go of away from the tower, at no place."""
    arm, part = "ars_x", scene.next_part("cross_frame_dispenser")
    for joint, value in zip(names.arm_joints(arm), _placement(scene.mission), strict=True):
        scene.set_joint_state(joint, float(value))
    mujoco.mj_forward(scene.model, scene.data)
    info = scene.part(part)
    joints = [scene.joint_position_world(f"bay1/{c}") for c in CORNERS]
    centre, axis = scene.assembly.grasp_line(arm)
    inward = sum(joints) / len(joints) - centre
    inward -= (inward @ axis) * axis
    inward /= np.linalg.norm(inward)
    seat = np.column_stack([axis, inward, np.cross(axis, inward)])
    tol = scene.mission.inspection
    m = mover(scene, arm)
    placements = []
    for shift in (0.0, 0.008):
        scene.place_part(part, centre - axis * (info.length / 2 - shift), seat)
        m.jaws(True)
        m.jaws(False)
        (release,) = scene.assembly.releases
        scene.assembly.releases.clear()
        placements.append(scene.placement(release))
    at_place, shifted = placements
    assert at_place.part == part and at_place.member == "bay1/cross_frame"
    assert at_place.within(tol["position_tolerance"], tol["angle_tolerance"]), at_place.describe()
    assert max(at_place.point_errors) < 0.002, at_place.describe()
    assert shifted.member == "bay1/cross_frame" and not shifted.within(tol["position_tolerance"], 1.0)
    assert shifted.position_error == pytest.approx(0.008, abs=0.0015), shifted.describe()
    assert shifted.angle_error < 0.005 and "bay1/cross_frame: centre 8" in shifted.describe()

    lifted = release.position + np.array([0.0, 0.0, 0.3])
    away = scene.placement(dataclasses.replace(release, position=lifted))
    assert away.member is None and not away.within(1.0, 1.0)
    assert away.as_dict()["angle_error_rad"] is None and "at no place" in away.describe()
