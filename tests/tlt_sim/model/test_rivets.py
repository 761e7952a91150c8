"""Rivets that can fail: each shot's outcome from where the gun stands and from injected faults; a
failed joint looks different to a camera and gives more under the bay's compression test; the
outcome is the twin's truth."""

import math

import mujoco
import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.config import REPO_ROOT
from tlt_sim.model.generate import HIDDEN_GROUP, RIVET_GROUP
from tlt_sim.model.rivet_outcomes import EFFECTS, FAULT_KINDS
from tlt_sim.model.scenario import parse_scenario
from tlt_sim.model.scene import Scene

from tlt_common.geometry.transforms import frame_from_axes as frame
from tlt_common.mission.schema import load_mission

ARM, GUN, FEEDER = "ars_x", "a", "rivet_dispenser_x"
MEMBER, JOINT = "bay1/vertical/x0_y0", "bay1/x0_y0"  # its lower rivet, at the bottom frame's corner 0
APPROACH = np.array([-0.3, 1.0, 0.0])  # the tool's z: past the lifter post, as the ARS comes in


def _bay_but_one_rivet(scene):
    """Bay 1 staged and riveted, but for MEMBER's rivet at JOINT; returns MEMBER's part and the
    weld that rivet makes."""
    placed = scene.stage_bay(1, skip_rivets=((MEMBER, JOINT),))
    part = scene.part(placed[MEMBER])
    frame_body = scene.part(placed["bay1/cross_frame"]).body
    return part, f"rivet/{part.body}/{frame_body}"


def _end_at(scene, part, joint):
    target = scene.truth.joint_position_world(joint)
    return min("ab", key=lambda e: np.linalg.norm(scene.truth.part_end(part.name, e) - target))


def _shoot(scene, mover, offset=(0.0, 0.0, 0.0), tilt_deg=0.0, load=True):
    """Gun a of ARS X on JOINT (bar along the vertical, tilted ``tilt_deg`` towards the bay), shifted
    by ``offset``; fire."""
    m = mover(scene, ARM)
    if load:
        m.load_rivet(GUN, FEEDER)
    across = np.cross(APPROACH, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    t = math.radians(tilt_deg)
    bar = math.cos(t) * np.array([0.0, 0.0, 1.0]) + math.sin(t) * across
    m.to(scene.truth.joint_position_world(JOINT) + np.asarray(offset), frame(bar, APPROACH), f"gun_{GUN}")
    return scene.fire_rivet(ARM, GUN)


def _from_the_fitting(scene, part, head, fitting):
    """How far the head's centre stands out from the axis of its end fitting, and along it (m)."""
    axis = np.zeros(9)
    mujoco.mju_quat2Mat(axis, fitting.quat)
    axis = axis.reshape(3, 3)[:, 2]
    d = head.pos - fitting.pos
    return float(np.linalg.norm(d - (d @ axis) * axis)), float(d @ axis)


def _scene_with(tmp_path, faults):
    mission = load_mission(REPO_ROOT / "missions" / "one_bay.yaml")
    scenario = parse_scenario({"name": "rivets", "faults": faults}, mission)
    return Scene(mission=mission, scenario=scenario, out_dir=tmp_path / "faulty")


def _solref(scene, equality):
    return list(scene.model.eq_solref[scene.assembly.eq[equality]])


@pytest.mark.parametrize(
    ("offset", "tilt_deg", "kind"),
    [
        ((0.0, 0.0, 0.0), 0.0, "good"),
        ((-0.006, -0.006, 0.0), 0.0, "good"),  # 8.5 mm off: within the 12 mm the fastener tolerates
        ((-0.014, -0.014, 0.0), 0.0, "proud_head"),  # 20 mm off
        ((0.0, 0.0, 0.0), 16.0, "partial_grip"),  # the bar 16 deg off the strut (tolerates 10)
    ],
)
def test_where_the_gun_stands_decides_the_joint(scene, mover, offset, tilt_deg, kind):
    part, weld = _bay_but_one_rivet(scene)
    shot = _shoot(scene, mover, np.array(offset), tilt_deg)
    assert shot.joined == [weld]  # good or not, the rivet holds the strut to the frame
    truth = scene.truth.rivet_joint(MEMBER, JOINT)
    assert (truth.kind, truth.cause, truth.equality, truth.shot) == (kind, "geometry", weld, 1)
    assert truth.offset_m == pytest.approx(np.linalg.norm(offset), abs=0.003)
    assert truth.angle_deg == pytest.approx(tilt_deg, abs=1.5)
    rivets = scene.edu["rivets"]
    assert _solref(scene, weld) == (
        scene.edu["physics"]["rivet_solref"] if kind == "good" else rivets["unseated_solref"]
    )
    head = scene.model.geom(f"{part.body}/rivet_{_end_at(scene, part, JOINT)}")
    assert head.group == RIVET_GROUP
    # The joints staged around it were good, and stay so.
    others = [r for r in scene.truth.rivet_joints() if r.equality != weld]
    assert len(others) == 11 and all(r.good and r.cause == "staged" for r in others)


@pytest.mark.parametrize("kind", FAULT_KINDS)
def test_an_injected_fault_spoils_its_joint_and_a_second_shot_repairs_it(tmp_path, mover, kind):
    scene = _scene_with(tmp_path, {"rivet_faults": [{"member": MEMBER, "joint": JOINT, "kind": kind}]})
    part, weld = _bay_but_one_rivet(scene)
    end = _end_at(scene, part, JOINT)
    head, shank = (scene.model.geom(f"{part.body}/rivet_{end}{s}") for s in ("", "#1"))
    fitting = scene.model.geom(f"{part.body}/fitting_{end}")
    effect = EFFECTS[kind]

    shot = _shoot(scene, mover)
    truth = scene.truth.rivet_joint(MEMBER, JOINT)
    assert (truth.kind, truth.cause, truth.shot) == (kind, "injected", 1)
    assert shot.outcomes == [truth]
    assert shot.loaded == (kind != "no_rivet")  # the rivet had fallen out of the gun
    assert scene.rivet_loaded(ARM, GUN) == (kind == "misfire")  # a misfire leaves it there
    active = bool(scene.data.eq_active[scene.assembly.eq[weld]])
    assert active == effect.joins and shot.joined == ([weld] if effect.joins else [])
    if effect.softer:
        assert _solref(scene, weld) == scene.edu["rivets"][effect.softer]
    assert (head.group == RIVET_GROUP) == (effect.head is not None)
    assert (shank.group == RIVET_GROUP) == (effect.head in ("proud", "partial"))
    rivets, radius = scene.edu["rivets"], scene.edu["parts"]["fitting_radius"]
    out, along = _from_the_fitting(scene, part, head, fitting)
    rise = {"proud": rivets["proud_height"], "partial": rivets["partial_grip_height"]}.get(effect.head, 0.0)
    assert out == pytest.approx(radius + rise, abs=1e-9)
    assert abs(along) == pytest.approx(
        rivets["wrong_hole_offset"] if effect.head == "wrong_hole" else 0.0, abs=1e-9
    )

    # A second shot at the joint (a new rivet unless the old one is still in the gun) sets it well.
    again = _shoot(scene, mover, load=kind != "misfire")
    truth = scene.truth.rivet_joint(MEMBER, JOINT)
    assert (truth.kind, truth.cause, truth.shot) == ("good", "geometry", 2)
    assert again.joined == [weld] and scene.data.eq_active[scene.assembly.eq[weld]]
    assert _solref(scene, weld) == scene.edu["physics"]["rivet_solref"]
    assert head.group == RIVET_GROUP and shank.group == HIDDEN_GROUP
    assert _from_the_fitting(scene, part, head, fitting) == pytest.approx((radius, 0.0), abs=1e-9)
    # on the fitting's side towards the EE that fired it, where its camera sees it
    toward = scene.data.geom_xpos[head.id] - scene.data.geom_xpos[fitting.id]
    assert float(toward @ -scene.body_pose(names.ee_body(ARM))[1][:, 2]) > 0.7 * radius
    scene.close()


def test_random_faults_spoil_joints_of_a_built_bay_as_drawn_by_the_seed(tmp_path):
    mission = load_mission(REPO_ROOT / "missions" / "one_bay.yaml")
    built = [m.id for m in mission.bay_members(1)]
    raw = {"name": "drawn", "built": built, "faults": {"random_rivet_faults": {"rate": 0.5, "seed": 4}}}
    scenario = parse_scenario(raw, mission)
    scene = Scene(mission=mission, scenario=scenario, out_dir=tmp_path / "drawn")
    truth = {(r.member, r.joint): r for r in scene.truth.rivet_joints()}
    assert set(truth) == {(m, r.joint) for m in built for r in mission.member(m).rivets}
    drawn = {key: scenario.rivets.random.draw(*key) for key in truth}
    assert {key: r.kind for key, r in truth.items()} == {key: k or "good" for key, k in drawn.items()}
    assert 0 < sum(k is not None for k in drawn.values()) < len(drawn)
    assert all((r.cause == "injected") == (not r.good) for r in truth.values())
    scene.close()


def test_a_shot_that_joins_nothing_leaves_an_earlier_rivet_as_it_was(tmp_path, mover):
    """A misfire on the second shot at a loose joint: the loose rivet stays, and stays the truth."""
    faults = {
        "rivet_faults": [
            {"member": MEMBER, "joint": JOINT, "kind": "loose"},
            {"member": MEMBER, "joint": JOINT, "kind": "misfire", "shot": 2},
        ]
    }
    scene = _scene_with(tmp_path, faults)
    _, weld = _bay_but_one_rivet(scene)
    _shoot(scene, mover)
    shot = _shoot(scene, mover)
    assert [o.kind for o in shot.outcomes] == ["misfire"]
    truth = scene.truth.rivet_joint(MEMBER, JOINT)
    assert (truth.kind, truth.shot) == ("loose", 1)
    assert scene.data.eq_active[scene.assembly.eq[weld]]
    assert [r.kind for r in scene.assembly.rivet_log if r.equality == weld] == ["loose", "misfire"]
    scene.close()


def test_a_later_members_shot_at_the_corner_leaves_an_earlier_bad_joint_bad(scene, mover):
    """The diagonal riveted at the corner of a vertical's proud rivet: its shot sets the diagonal's
    joint only; the vertical's stays proud until a shot meant for it."""
    diagonal = "bay1/diagonal/face_x0"
    placed = scene.stage_bay(1, skip_rivets=((diagonal, JOINT),), rivet_kinds={(MEMBER, JOINT): "proud_head"})
    shot = _shoot(scene, mover)
    assert [(o.member, o.joint) for o in shot.outcomes] == [(diagonal, JOINT)]
    assert shot.joined == [
        f"rivet/{scene.part(placed[diagonal]).body}/{scene.part(placed['bay1/cross_frame']).body}"
    ]
    assert scene.truth.rivet_joint(MEMBER, JOINT).kind == "proud_head"
    # Nothing new at the corner now: the second shot rivets again what is bad there, the vertical
    # (and the diagonal, which the bar along the vertical reached 45 degrees askew).
    again = _shoot(scene, mover)
    assert {(o.member, o.kind, o.shot) for o in again.outcomes} == {
        (MEMBER, "good", 2),
        (diagonal, "partial_grip", 2),
    }
    assert shot.outcomes[0].kind == "partial_grip" and shot.outcomes[0].angle_deg == pytest.approx(
        45.0, abs=2.0
    )


def test_a_foundation_rivet_turns_out_as_the_gun_stands_too(scene, mover):
    placed = scene.stage_bay(1)
    frame_body = scene.part(placed["bay1/cross_frame"]).body
    m = mover(scene, ARM)
    m.load_rivet(GUN, FEEDER)
    corner = scene.site_position(names.corner_site(frame_body, 0))
    m.to(corner + np.array([0.0, 0.0, 0.02]), frame([0, 0, 1], APPROACH), f"gun_{GUN}")
    shot = scene.fire_rivet(ARM, GUN)
    name = f"foundation/0/{frame_body}"
    assert shot.joined == [name]
    truth = scene.truth.rivet_joint("foundation/x0_y0", JOINT)
    assert (truth.kind, truth.cause, truth.equality) == ("proud_head", "geometry", name)
    assert _solref(scene, name) == scene.edu["rivets"]["unseated_solref"]


def _joint_view(scene, part, end, lookat):
    """A frame of the head at ``end`` of ``part`` from 0.2 m off, to one side of the fitting."""
    rot = scene.body_pose(part.body)[1]
    d = rot[:, 0] + 0.9 * rot[:, 1] + 0.3 * rot[:, 2]
    d /= np.linalg.norm(d)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = lookat
    cam.distance = 0.2
    cam.azimuth = math.degrees(math.atan2(-d[1], -d[0]))
    cam.elevation = math.degrees(math.asin(-d[2]))
    return scene.render(cam, 160, 120, depth=False)


def test_a_failed_joint_looks_different_to_a_camera(scene):
    looks, lookat = {}, None
    for kind in ("good", "loose", "proud_head", "partial_grip", "wrong_hole", "no_rivet"):
        scene.reset()
        part = scene.part(scene.stage_bay(1, rivet_kinds={(MEMBER, JOINT): kind})[MEMBER])
        end = _end_at(scene, part, JOINT)
        head = f"{part.body}/rivet_{end}"
        if lookat is None:  # where a good head seats: every view looks there
            lookat = scene.data.geom_xpos[scene.model.geom(head).id].copy()
        frame_ = _joint_view(scene, part, end, lookat)
        assert frame_.class_of(head) == "rivet"
        pixels = frame_.instances().get(head, 0)
        centre = np.argwhere(frame_.mask(head)).mean(axis=0) if pixels else None
        looks[kind] = (pixels, centre)
    good, centre = looks["good"]
    assert good > 20
    assert looks["loose"][0] == good and np.allclose(looks["loose"][1], centre)  # loose looks good
    assert looks["no_rivet"][0] == 0  # no head at all
    assert looks["proud_head"][0] > 1.2 * good  # the head stands out on its shank
    assert good < looks["partial_grip"][0] < looks["proud_head"][0]
    assert np.linalg.norm(looks["wrong_hole"][1] - centre) > 5.0  # pixels: a head elsewhere


@pytest.mark.parametrize("kind", ["proud_head", "partial_grip", "loose", "wrong_hole"])
def test_a_failed_joint_gives_more_under_the_bay_compression_test(scene, kind):
    placed = scene.stage_bay(1)
    weld = f"rivet/{scene.part(placed[MEMBER]).body}/{scene.part(placed['bay1/cross_frame']).body}"
    good = scene.compression_test(force_n=200.0, settle_s=0.3)
    scene.reset()
    scene.stage_bay(1, rivet_kinds={(MEMBER, JOINT): kind})
    bad = scene.compression_test(force_n=200.0, settle_s=0.3)
    assert bad.displacement_m > 1.5 * good.displacement_m
    assert weld in good.slips_m and good.slips_m[weld] > 0
    if EFFECTS[kind].joins:  # the joint itself slips several times as far as a good one
        assert bad.slips_m[weld] > 3 * good.slips_m[weld]
    else:
        assert weld not in bad.slips_m


def test_staging_refuses_a_rivet_kind_at_a_joint_the_bay_has_no_rivet_at(scene):
    with pytest.raises(ValueError, match="no rivet at bay1/vertical/x0_y0 bay1/x1_y1"):
        scene.stage_bay(1, rivet_kinds={(MEMBER, "bay1/x1_y1"): "loose"})


def _lifter_push(scene, rise_m=0.002, settle_s=1.0):
    """The Test Bay's push as the CRS makes it: each carriage commanded ``rise_m`` up, the Top
    Grippers holding the frame above; returns how far each carriage's encoder says it went (m)."""
    lifter = [names.lifter_joint(i) for i in range(4)]
    scene.advance(0.3)
    start = [scene.position(j) for j in lifter]
    for joint, q in zip(lifter, start, strict=True):
        scene.command_position(joint, q + rise_m)
    scene.advance(settle_s)
    return np.array([scene.position(j) - q for j, q in zip(lifter, start, strict=True)])


@pytest.mark.parametrize("kind", ["loose", "proud_head", "wrong_hole"])
def test_the_lifters_own_encoders_show_a_bad_joint_under_the_test_bays_push(scene, kind):
    """The carriages are position-servoed against the bay: where the bay gives more, its carriage
    gets further. Corner 0's carriage (under the bad joint, x0_y0) runs on past the others."""
    scene.stage_bay(1)
    good = _lifter_push(scene)
    assert np.ptp(good) < 1e-5 and good.min() > 0.0005  # four equal corners
    scene.reset()
    scene.stage_bay(1, rivet_kinds={(MEMBER, JOINT): kind})
    bad = _lifter_push(scene)
    assert int(np.argmax(bad)) == 0
    assert bad[0] - good[0] > 0.00015  # 30 encoder counts at 200 000 counts per m
