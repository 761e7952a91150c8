"""Assembly physics: grasp, carry, place and rivet a strut; bay stiffness; bays stacking."""

import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.config import REPO_ROOT
from tlt_sim.model.scene import Scene

from tlt_common.geometry.transforms import frame_from_axes as frame


def test_strut_is_picked_carried_placed_riveted_and_holds_under_compression(scene, mover):
    arm, part = "ars_x", "vertical_dispenser_x/0"
    m = mover(scene, arm)
    for side in ("a", "b"):
        assert not scene.fire_rivet(arm, side).loaded  # nothing loaded yet: a dry shot
        m.load_rivet(side, "rivet_dispenser_x")
    assert (
        scene.dispenser_count("rivet_dispenser_x") == scene.mission.dispensers["rivet_dispenser_x"].count - 2
    )

    m.pick(part)
    assert scene.holding(arm) == scene.part(part).body
    assert scene.part_state(part) == "grasped"
    # The jaws stop on the tube: the servo reads short of its goal, which is how the ARS verifies a grasp.
    jaw = scene.position(names.grasp_joint(arm, "a"))
    assert jaw < scene.edu["end_effector"]["jaw_range"][1] - 0.2
    assert scene.effort(names.grasp_joint(arm, "a")) > 3.0  # squeezing the tube (N m)

    start = scene.body_pose(scene.part(part).body)[0]
    scene.stage_member("bay1/cross_frame")
    top, bottom = scene.joint_position_world("bay0/x0_y0"), scene.joint_position_world("bay1/x0_y0")
    # Tool turned off the arm's diagonal: the lifter post stands on it, between the arm and the corner.
    placing = frame(bottom - top, [-0.3, 1.0, 0.0])
    m.to((top + bottom) / 2, placing)
    assert np.linalg.norm(scene.body_pose(scene.part(part).body)[0] - start) > 1.0  # carried
    assert np.linalg.norm(scene.truth.part_end(part, "a") - top) < 2e-3
    assert np.linalg.norm(scene.truth.part_end(part, "b") - bottom) < 2e-3

    shot_a, shot_b = scene.fire_rivet(arm, "a"), scene.fire_rivet(arm, "b")
    cross_frame = scene.part(scene.assembly.latches[0].split("part/")[1]).body
    assert shot_a.joined == [f"rivet/{scene.part(part).body}/payload"]
    assert shot_b.joined == [f"rivet/{scene.part(part).body}/{cross_frame}"]
    m.jaws(False)
    assert scene.holding(arm) is None
    assert scene.part_state(part) == "placed"

    for member in scene.mission.bay_members(1):
        if member.id not in ("bay1/cross_frame", "bay1/vertical/x0_y0"):
            scene.stage_member(member.id)
    result = scene.compression_test(force_n=200.0, settle_s=0.3)
    assert 0.0 < result.displacement_m < 0.005
    assert np.linalg.norm(scene.truth.part_end(part, "a") - top) < 2e-3
    assert np.linalg.norm(scene.truth.part_end(part, "b") - bottom) < 2e-3


def test_released_part_that_nothing_holds_falls(scene, mover):
    arm, part = "ars_y", "vertical_dispenser_y/0"
    m = mover(scene, arm)
    m.pick(part)
    assert scene.holding(arm) is not None
    m.jaws(False, settle_s=1.5)
    assert scene.part_state(part) == "dropped"
    body = scene.part(part).body
    assert scene.body_pose(body)[0][2] < 0.1  # on the floor
    weight = scene.model.body_subtreemass[scene.model.body(body).id] * 9.81
    assert scene.truth.contact_force(body)[2] == pytest.approx(weight, rel=0.1)  # the floor carries it


def test_grasp_holds_while_jaws_ease_and_lets_go_once_they_open(scene, mover):
    """The jaws count as closed past the contact angle less JAW_CLOSED and as open again only below
    it less JAW_OPEN: a jaw easing off in between keeps the part (no flicker), one opening lets go.
    The rules run on crossings of these thresholds only, so this checks that both are seen."""
    from tlt_sim.model.assembly import JAW_CLOSED, JAW_OPEN

    arm, part = "ars_x", "vertical_dispenser_x/0"
    mover(scene, arm).pick(part)
    body = scene.part(part).body
    assert scene.holding(arm) == body
    contact = scene.edu["end_effector"]["jaw_contact"]
    jaws = [names.grasp_joint(arm, side) for side in ("a", "b")]
    for jaw in jaws:
        scene.set_joint_state(jaw, contact - (JAW_CLOSED + JAW_OPEN) / 2)
    scene.assembly.update()
    assert scene.holding(arm) == body, "easing off between the thresholds keeps the grasp"
    scene.set_joint_state(jaws[0], contact - JAW_OPEN - 0.01)
    scene.assembly.update()
    assert scene.holding(arm) is None and scene.part_state(part) != "grasped"


def test_jaws_hold_a_diagonal_where_it_lies_along_them_and_miss_it_past_its_tube(scene, mover):
    """The ARS takes a diagonal off its middle (gun 0 on its end): the grasp keeps that offset. A
    grasp with a jaw beyond the tube, on an end fitting, takes nothing."""
    arm, part = "ars_x", "diagonal_dispenser_x/0"
    info = scene.part(part)
    m = mover(scene, arm)
    m.pick(part, along=-0.155)
    body = scene.part(part).body
    assert scene.holding(arm) == body
    centre, axis = scene.assembly.grasp_line(arm)
    pos, rot = scene.body_pose(body)
    middle = pos + rot @ info.grasps[0][0]
    assert abs(abs(float((middle - centre) @ axis)) - 0.155) < 0.005
    assert np.linalg.norm(np.cross(middle - centre, axis)) < 0.005  # drawn onto the jaws' line

    m.jaws(False, settle_s=0.3)
    scene.reset()
    jaws = np.linalg.norm(scene.site_position(f"{arm}/grip_b") - scene.site_position(f"{arm}/grip_a")) / 2
    m.pick(part, along=info.grasp_span - jaws + 0.02)
    assert scene.holding(arm) is None


def test_top_grippers_carry_the_payloads_weight(scene):
    scene.advance(0.2)
    total = sum(scene.truth.constraint_force(f"top/{i}/payload") for i in range(4))
    weight = scene.model.body_subtreemass[scene.model.body("payload").id] * 9.81
    assert total == pytest.approx([0.0, 0.0, weight], abs=1e-3 * weight)


def test_empty_grasp_closes_fully_and_holds_nothing(scene):
    arm = "ars_x"
    for side in ("a", "b"):
        scene.command_position(names.grasp_joint(arm, side), scene.edu["end_effector"]["jaw_range"][1])
    scene.advance(0.8)
    assert scene.holding(arm) is None
    assert scene.position(names.grasp_joint(arm, "a")) == pytest.approx(1.4, abs=0.02)
    assert abs(scene.effort(names.grasp_joint(arm, "a"))) < 1.0  # closed on nothing


def test_bay_missing_a_rivet_is_less_stiff(scene):
    scene.stage_bay(1)
    full = scene.compression_test(force_n=200.0, settle_s=0.3)
    scene.reset()
    scene.stage_bay(1, skip_rivets=(("bay1/vertical/x0_y0", "bay1/x0_y0"),))
    missing = scene.compression_test(force_n=200.0, settle_s=0.3)
    assert full.displacement_m > 0
    assert missing.displacement_m > 1.5 * full.displacement_m
    assert missing.stiffness_n_per_m < full.stiffness_n_per_m


def test_compression_test_needs_both_grippers_on_different_frames(scene):
    with pytest.raises(ValueError, match="Active Grippers"):
        scene.compression_test()


def test_bays_stack_as_the_lifter_raises_them(tmp_path):
    scene = Scene(mission=REPO_ROOT / "missions" / "two_bay.yaml", out_dir=tmp_path / "two_bay")
    placed = scene.stage_bay(1)
    frame_body = scene.part(placed["bay1/cross_frame"]).body
    payload_z = scene.body_pose("payload")[0][2]
    height, build = scene.mission.bay_height, scene.edu["lifter"]["build_position"]
    lifter = [names.lifter_joint(i) for i in range(4)]
    # Fast-forward the lead screws and pins: the real travel takes 15 s at 0.05 m/s.
    for joint in lifter:
        scene.servos._vmax[scene.servos._index(joint)] = 0.5
    for i in range(4):
        scene.servos._vmax[scene.servos._index(names.top_gripper(i))] = 0.1
        scene.command_position(names.top_gripper(i), 0.0)
    scene.advance(0.5)
    assert scene.assembly.pins == [None] * 4
    for joint in lifter:
        scene.command_position(joint, build + height)
    scene.advance(2.0)
    assert scene.body_pose("payload")[0][2] - payload_z == pytest.approx(height, abs=3e-3)
    for i in range(4):
        scene.command_position(names.top_gripper(i), scene.edu["top_grippers"]["stroke"])
    scene.advance(0.5)
    assert scene.assembly.pins == [frame_body] * 4
    for i in range(4):
        scene.command_position(names.active_gripper(i), 0.0)
    scene.advance(0.6)
    for joint in lifter:
        scene.command_position(joint, build)
    scene.advance(2.0)
    assert scene.assembly.latches == [None] * 4
    assert scene.body_pose(frame_body)[0][2] == pytest.approx(scene.info.top_level, abs=3e-3)
    assert scene.body_pose("payload")[0][2] - payload_z == pytest.approx(height, abs=3e-3)
    # The second bay goes in below the first, at the build level, and carries load like the first.
    second = scene.part(scene.stage_bay(2)["bay2/cross_frame"]).body
    assert scene.body_pose(second)[0][2] == pytest.approx(scene.edu["site"]["build_level"], abs=3e-3)
    result = scene.compression_test(force_n=200.0, settle_s=0.3)
    assert (result.top, result.bottom) == (frame_body, second)
    assert 0.0 < result.displacement_m < 0.005
    scene.close()


def test_last_bay_is_riveted_to_the_foundation(scene, mover):
    placed = scene.stage_bay(1)
    frame_body = scene.part(placed["bay1/cross_frame"]).body
    arm = "ars_x"
    m = mover(scene, arm)
    m.load_rivet("a", "rivet_dispenser_x")
    corner = scene.site_position(names.corner_site(frame_body, 0))
    m.to(corner, frame([0, 0, 1], [-0.3, 1.0, 0]), "gun_a")
    shot = scene.fire_rivet(arm, "a")
    assert shot.joined == [f"foundation/0/{frame_body}"]


def test_a_scenario_starts_members_built_riveted_and_held(tmp_path):
    from tlt_sim.model.scenario import parse_scenario

    mission = Scene(out_dir=tmp_path / "plain").mission
    last = "bay1/diagonal/face_y1"
    built = [m.id for m in mission.bay_members(1) if m.id != last]
    scenario = parse_scenario({"name": "late", "built": built[::-1], "faults": {}}, mission)
    assert scenario.built == tuple(built)  # build order, whatever the file's
    scene = Scene(mission=mission, scenario=scenario, out_dir=tmp_path / "late")
    frame_body = scene.part("cross_frame_dispenser/0").body
    assert scene.assembly.latches == [frame_body] * 4  # the Active Grippers hold the frame
    scene.advance(1.0)  # and everything stays where the build would have left it
    taken: dict[str, int] = {}
    for member_id in built:
        member = mission.member(member_id)
        index = taken[member.dispenser] = taken.get(member.dispenser, -1) + 1
        part = f"{member.dispenser}/{index}"  # parts come out of a dispenser in order
        assert scene.part_state(part) == "placed"
        if member.kind != "cross_frame":
            ends = sorted((scene.truth.part_end(part, e) for e in ("a", "b")), key=lambda p: p[2])
            place = sorted((scene.joint_position_world(j) for j, _ in member.joints), key=lambda p: p[2])
            assert max(np.linalg.norm(e - p) for e, p in zip(ends, place, strict=True)) < 2e-3, member_id
    assert scene.next_part("diagonal_dispenser_y") == "diagonal_dispenser_y/1"
    fired = sum(r.dispenser == "rivet_dispenser_y" for m in built for r in mission.member(m).rivets)
    assert scene.dispenser_count("rivet_dispenser_y") == mission.dispensers["rivet_dispenser_y"].count - fired
    result = scene.compression_test(force_n=200.0, settle_s=0.3)
    assert 0.0 < result.displacement_m < 0.005
    scene.close()
