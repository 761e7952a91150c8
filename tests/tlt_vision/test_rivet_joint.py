"""A riveted joint judged from the EE camera beside the gun that set it, on twin renders of each
way a rivet turns out: the rivet masks stand in for Mask R-CNN's (the twin's segmentation), the
depth is exact or as a D405 gives it, and where the hole should be comes from the mission's joint,
the member's axis and the EE's pose, never from the twin's truth of the head."""

from __future__ import annotations

import numpy as np
import pytest
from tlt_sim.model import ik, names
from tlt_sim.model.camera_sensor import load_camera_sensors
from tlt_sim.model.config import REPO_ROOT
from tlt_sim.model.scenario import parse_scenario
from tlt_sim.model.scene import Scene

from tlt_common.geometry.transforms import frame_from_axes as frame
from tlt_common.mission.schema import load_mission
from tlt_vision.detections import Detection
from tlt_vision.inspection.rivet_joint import (
    CANNOT_JUDGE,
    GOOD,
    NO_HEAD,
    UNSEATED,
    WRONG_HOLE,
    HoleView,
    judge_rivet_joint,
)

ARM, GUN, FEEDER = "ars_x", "a", "rivet_dispenser_x"
MEMBER, JOINT = "bay1/vertical/x0_y0", "bay1/x0_y0"
APPROACH = np.array([-0.3, 1.0, 0.0])
CAMERA = names.d405_camera(ARM, GUN)
SEEN_AS = {
    "good": GOOD,
    "loose": GOOD,  # a loose joint looks good: the compression test is its check
    "proud_head": UNSEATED,
    "partial_grip": UNSEATED,
    "wrong_hole": WRONG_HOLE,
    "no_rivet": NO_HEAD,
    "misfire": NO_HEAD,
}


def _pose(scene, position, rotation, point):
    waypoints = ik.plan(scene.model, scene.data.qpos, ARM, position, rotation, scene.ee_point(ARM, point))
    assert waypoints is not None, f"no way to {position}"
    scene.pose_arm(ARM, waypoints[-1])


def _load(scene):
    pickup = scene.site_position(f"dispenser/{FEEDER}/pickup")
    for yaw in np.arange(8) * np.pi / 4:
        rotation = frame([np.cos(yaw), np.sin(yaw), 0.0], [0.0, 0.0, -1.0])
        if ik.plan(scene.model, scene.data.qpos, ARM, pickup, rotation, scene.ee_point(ARM, f"gun_{GUN}")):
            _pose(scene, pickup, rotation, f"gun_{GUN}")
            assert scene.load_rivet(ARM, GUN)
            return
    raise AssertionError("no way to the feeder")


def _hole_view(scene, frame_):
    """Where a seated head of MEMBER at JOINT sits, from the mission and the parts' drawing; its
    outward side is the one the gun fired from (the EE's pose, which the ARS knows)."""
    joints = dict(scene.mission.member(MEMBER).joints)
    joint = scene.truth.joint_position_world(JOINT)
    other = scene.truth.joint_position_world(next(j for j in joints if j != JOINT))
    axis = (other - joint) / np.linalg.norm(other - joint)
    parts = scene.edu["parts"]
    out = -scene.body_pose(names.ee_body(ARM))[1][:, 2]
    out = out - (out @ axis) * axis
    out /= np.linalg.norm(out)
    hole = (
        joint
        + axis * (parts["corner_size"] / 2 + parts["fitting_length"] / 2)
        + parts["fitting_radius"] * out
    )
    return HoleView.from_world(hole, out, axis, frame_.position, frame_.rotation)


def _rivets(frame_):
    """The frame's rivet instances as detections (the stand-in for Mask R-CNN's)."""
    shown = frame_.instances()
    return [
        Detection("rivet", frame_.mask(name), object_id=name)
        for name, cls in zip(frame_.labels.instance_names, frame_.labels.classes, strict=True)
        if cls == "rivet" and name in shown
    ]


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    """Each outcome at JOINT, as D405 a sees it right after the shot (and D405 b, at the bar's
    other end, for the good one)."""
    mission = load_mission(REPO_ROOT / "missions" / "one_bay.yaml")
    out = {}
    for kind in SEEN_AS:
        faults = (
            {} if kind == "good" else {"rivet_faults": [{"member": MEMBER, "joint": JOINT, "kind": kind}]}
        )
        scenario = parse_scenario({"name": kind, "faults": faults}, mission)
        scene = Scene(mission=mission, scenario=scenario, out_dir=tmp_path_factory.mktemp(kind))
        scene.stage_bay(1, skip_rivets=((MEMBER, JOINT),))
        _load(scene)
        _pose(scene, scene.truth.joint_position_world(JOINT), frame([0.0, 0.0, 1.0], APPROACH), f"gun_{GUN}")
        shot = scene.fire_rivet(ARM, GUN)
        assert [o.kind for o in shot.outcomes] == [kind]
        frame_ = scene.render(CAMERA, 320, 240)
        other = scene.render(names.d405_camera(ARM, "b"), 320, 240) if kind == "good" else None
        out[kind] = (frame_, _hole_view(scene, frame_), other)
        scene.close()
    return out


@pytest.mark.parametrize("kind", list(SEEN_AS))
def test_each_outcome_is_judged_from_the_exact_frame(shots, kind):
    frame_, view, _ = shots[kind]
    judged = judge_rivet_joint(_rivets(frame_), frame_.depth, frame_.intrinsics, view)
    assert judged.verdict == SEEN_AS[kind], judged.reason
    if judged.head is not None:
        assert judged.pixels > 100
        assert np.linalg.norm(judged.head - view.hole) < 0.025


@pytest.mark.parametrize("kind", list(SEEN_AS))
def test_each_outcome_is_judged_on_the_d405s_depth(shots, kind):
    frame_, view, _ = shots[kind]
    sensors = load_camera_sensors()
    sensor = sensors.for_camera(CAMERA)
    for index in range(3):
        _, depth = sensor.apply(
            frame_.rgb, frame_.depth, frame_.intrinsics.fx, sensors.frame_rng(CAMERA, index)
        )
        judged = judge_rivet_joint(_rivets(frame_), depth, frame_.intrinsics, view)
        assert judged.verdict == SEEN_AS[kind], judged.reason


def test_figures_tell_how_far_out_and_along_a_head_stands(shots):
    judged = {
        kind: judge_rivet_joint(_rivets(f), f.depth, f.intrinsics, v)
        for kind, (f, v, _) in shots.items()
        if kind in ("good", "partial_grip", "proud_head", "wrong_hole")
    }
    assert judged["good"].height_m < judged["partial_grip"].height_m < judged["proud_head"].height_m
    assert judged["proud_head"].height_m - judged["good"].height_m == pytest.approx(0.009, abs=0.0025)
    assert abs(judged["wrong_hole"].along_m) == pytest.approx(0.016, abs=0.002)
    assert abs(judged["good"].along_m) < 0.002


def test_a_hole_hidden_or_without_depth_cannot_be_judged_never_passed(shots):
    frame_, view, other = shots["good"]
    rivets = _rivets(frame_)
    k = frame_.intrinsics
    u = round(float(k.fx * view.hole[0] / view.hole[2] + k.cx))
    v = round(float(k.fy * view.hole[1] / view.hole[2] + k.cy))

    holed = frame_.depth.copy()
    holed[v - 25 : v + 26, u - 25 : u + 26] = 0.0
    judged = judge_rivet_joint(rivets, holed, k, view)
    assert (judged.verdict, judged.judged) == (CANNOT_JUDGE, False)
    assert "depth missing" in judged.reason

    blocked = frame_.depth.copy()
    blocked[v - 25 : v + 26, u - 25 : u + 26] = view.hole[2] - 0.1  # something between camera and joint
    judged = judge_rivet_joint(rivets, blocked, k, view)
    assert judged.verdict == CANNOT_JUDGE and "view blocked" in judged.reason

    headless = frame_.depth.copy()
    for det in rivets:
        headless[det.mask] = 0.0  # the head seen, its depth lost (a highlight)
    judged = judge_rivet_joint(rivets, headless, k, view)
    assert judged.verdict == CANNOT_JUDGE and "cannot place" in judged.reason

    # The camera at the bar's other end does not see this joint at all.
    judged = judge_rivet_joint(_rivets(other), other.depth, other.intrinsics, _moved(view, frame_, other))
    assert judged.verdict == CANNOT_JUDGE and (
        "outside the view" in judged.reason or "behind" in judged.reason
    )


def test_only_rivet_masks_count_as_heads(shots):
    frame_, view, _ = shots["good"]
    fittings = [Detection("end_fitting", d.mask) for d in _rivets(frame_)]
    judged = judge_rivet_joint(fittings, frame_.depth, frame_.intrinsics, view)
    assert judged.verdict == NO_HEAD


def _moved(view, seen, other):
    """``view`` (in ``seen``'s optical frame) in ``other``'s."""
    world = [
        seen.rotation @ view.hole + seen.position,
        seen.rotation @ view.outward,
        seen.rotation @ view.along,
    ]
    return HoleView.from_world(world[0], world[1], world[2], other.position, other.rotation)
