"""Parts held by ARS X at their place, measured by the arm's own D405s (CheckAlignment).

Held at the middle of a side, a cross frame is centimetres from the EE cameras: neither sees enough
of it for the frame's own pose, but each sees the corner joint at its end of the held side; a
strut held at its middle likewise shows each D405 the end fitting at its end. The twin
(``tlt_sim.model.Scene``) puts ARS X at the placement configuration the planner picks for
``bay1/cross_frame`` (the first usable candidate, as the ARS's coarse and fine approach take it),
seats the frame in the grasp as the twin's grasp does (or 10 mm along its side, a grasp that
caught it off-centre), renders both D405s and runs what CheckAlignment runs on them: the vision
pipeline's corner joint poses (C-3PO, the shipped weights; the twin's segmentation, as the launch
set runs vision) and :func:`tlt_vision.inspection.held_part_alignment`. The same for the far
vertical ``bay1/vertical/x0_y1`` that ARS X adds once the cross frame is in place.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from tlt_ars.planning.reachability import reach_target
from tlt_ars.planning.targets import part_in_tool, placement_targets
from tlt_ars.planning.world import build_scene, load_scene_config
from tlt_common.config_schema import load_yaml
from tlt_common.mission.schema import load_mission
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.detections import detections_near
from tlt_vision.inspection import corner_joint_prior, expected_pieces, held_part_alignment
from tlt_vision.node_config import load_config
from tlt_vision.part_inspection import PartInspector
from tlt_vision.segmentation_source import MaskRcnnSegmenter, TwinLabels

scene_mod = pytest.importorskip("tlt_sim.model.scene")
names = pytest.importorskip("tlt_sim.model.names")

ROOT = Path(__file__).resolve().parents[2]
RUN = load_yaml(ROOT / "config" / "twin" / "run.yaml")
ARS_X = load_yaml(ROOT / "config" / "ars" / "ars_x.yaml")
MISSION = load_mission(ROOT / "missions" / "one_bay.yaml")
MEMBER = MISSION.member("bay1/cross_frame")
CAMERAS = ("ars_x/d405_a", "ars_x/d405_b")
RESOLUTION = load_scene_config().planning["dense_check_resolution"]


@pytest.fixture(scope="module")
def placement():
    """ARS X's joints and tool pose at the frame's place, and the frame's corners there (world)."""
    cfg = load_scene_config()
    kw = dict(placed=set(), bay=1, carrying="cross_frame")
    free = build_scene(cfg, "ars_x", MISSION, contact=False, **kw)
    contact = build_scene(cfg, "ars_x", MISSION, contact=True, **kw)
    target = placement_targets(cfg, MISSION, MEMBER, "ars_x")[0]
    _, q = reach_target(free, contact, target, cfg.home("ars_x"), cfg.planning["dense_check_resolution"])
    vision = load_config().raw["site"]
    level = vision["build_level"] + MISSION.bay_height
    origin = np.asarray(vision["base_origin"]) + np.array([0.0, 0.0, level])
    corners = np.array([origin + np.asarray(p) for _, p in MEMBER.joints])
    return q, cfg.kinematics("ars_x").forward(q), corners


@pytest.fixture(scope="module")
def inspector():
    cfg = load_config()
    return PartInspector(cfg, load_mission(cfg.mission_path))


def _corners_seen(
    placement, inspector, tmp_path, shift: float, dq=(0.0,) * 6, prior: bool = True
) -> list[np.ndarray]:
    """Certified corner joints (world) in both D405 frames, the frame ``shift`` m along its side,
    the arm ``dq`` (rad) off the placement configuration (a controller's tracking error)."""
    q = np.asarray(placement[0]) + np.asarray(dq)
    scene = scene_mod.Scene(out_dir=tmp_path)
    with scene:
        for j, v in zip(names.arm_joints("ars_x"), q, strict=True):
            scene.set_joint_state(j, float(v))
        mujoco.mj_forward(scene.model, scene.data)
        part = scene.part(scene.next_part("cross_frame_dispenser"))
        centre, axis = scene.assembly.grasp_line("ars_x")
        tool = load_scene_config().kinematics("ars_x").forward(q)
        y = tool[:3, 1] - (tool[:3, 1] @ axis) * axis
        y /= np.linalg.norm(y)
        start = centre - axis * (part.length / 2 - shift)
        scene.place_part(part.name, start, np.column_stack([axis, y, np.cross(axis, y)]))
        return _pieces_seen(scene, inspector, "corner_joint", "bay", placement[2], prior)


def _pieces_seen(
    scene, inspector, piece: str, pipeline: str, places: np.ndarray, prior: bool = False, segmenter=None
) -> list[np.ndarray]:
    """Certified ``piece`` poses (world) in both D405 frames, as CheckAlignment takes them: only
    the pieces within the gate's reach of ``places`` get a pose, a corner joint's fit also
    started from its place (``prior``). Segmented by ``segmenter`` (a MaskRcnnSegmenter, the
    node's score floor applied) or the twin's labels."""
    seen = []
    size = RUN["cameras"]["d405"]
    config = load_config()
    radius = config.raw["held_piece_gate"] + inspector.estimators[piece].model.diameter / 2
    for camera in CAMERAS:
        f = scene.render(camera, size["width"], size["height"], antialias=RUN["cameras"]["antialias"])
        if segmenter is None:
            found = TwinLabels.detect_render(f, camera)
        else:
            frame = CameraFrame(
                camera,
                0.0,
                f"{camera}_optical",
                f.intrinsics,
                f.intrinsics.matrix,
                {"rgb": f.rgb, "depth": f.depth},
            )
            floor = config.raw["segmentation"]["min_score"]
            found = [d for d in segmenter.detect(frame) if d.score >= floor]
        found = [d for d in found if d.object_class == piece]
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = f.rotation, f.position
        found = detections_near(found, f.depth, f.intrinsics, pose, places, radius)
        start = corner_joint_prior(places, pose) if prior else None
        for o in inspector.observe(pipeline, found, f.depth, f.intrinsics, f.rgb, start):
            if o.estimate is not None and o.estimate.certified:
                seen.append(f.rotation @ o.estimate.translation + f.position)
    return seen


def test_each_d405_sees_the_corner_joint_at_its_end_and_the_frame_is_aligned(placement, inspector, tmp_path):
    _, tool, corners = placement
    seen = _corners_seen(placement, inspector, tmp_path, 0.0)
    assert len(seen) == 2, seen
    result = held_part_alignment("cross_frame", corners, seen, tool, inspector.tol, gate=0.1)
    assert result.aligned, result.reason
    assert result.matched == 2 and result.position_error < 0.002
    assert np.linalg.norm(result.held[:3, 3] - tool[:3, 3]) < 0.002


def test_a_frame_caught_off_centre_is_measured_and_the_correction_puts_it_in_place(
    placement, inspector, tmp_path
):
    _, tool, corners = placement
    seen = _corners_seen(placement, inspector, tmp_path, 0.01)
    result = held_part_alignment("cross_frame", corners, seen, tool, inspector.tol, gate=0.1)
    assert not result.aligned and result.position_error == pytest.approx(0.01, abs=0.002), result
    assert "from its place" in result.reason
    # The ARS's correction (tlt_ars.behaviours.vision.corrected_target, target = the tool now) moves
    # the tool by the measured error the other way: the frame's corners land on their place.
    corrected = tool @ np.linalg.inv(result.held) @ tool
    moved = [corrected @ np.linalg.inv(tool) @ np.append(p, 1.0) for p in seen]
    assert max(np.min(np.linalg.norm(corners - m[:3], axis=1)) for m in moved) < 0.002


def test_corner_joints_are_certified_with_the_arm_a_little_off_its_placement(placement, inspector, tmp_path):
    """The arm a few milliradians off its placement configuration (as the controller leaves it)
    and the frame a millimetre or two along its grasp. In a sweep of such offsets the keypoint
    detector's fit of D405 a's partial cube view once settled turned (3.8 mm Chamfer, no face
    matched) and the joint was not certified, as whole runs failed CheckAlignment of the cross
    frame; the fit also started at the joint's place (:func:`corner_joint_prior`) certified it.
    Which offsets fit turned hangs on the last digits of the rendered view, so the passes over a
    few offsets (that one first) are what is asserted."""
    _, tool, corners = placement
    rng = np.random.default_rng(7)
    cases = [((0.000427286, 0.000434644, 0.004235678, -0.002224042, -0.000755210, 0.004085543), 0.0012934)]
    cases += [(tuple(rng.normal(0.0, 0.002, 6)), float(rng.normal(0.0, 0.002))) for _ in range(2)]
    for dq, shift in cases:
        seen = _corners_seen(placement, inspector, tmp_path, shift, dq)
        assert len(seen) == 2, (dq, shift, seen)
        result = held_part_alignment("cross_frame", corners, seen, tool, inspector.tol, gate=0.1)
        assert result.matched == 2 and result.position_error < 0.01, (dq, shift, result)


def _perpendiculars(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.cross(u, [0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.cross(u, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    return a, np.cross(u, a)


def _held_strut(inspector, tmp_path, member_id: str, off: float = 0.0, segmenter=None):
    """ARS X holding ``member_id``'s strut at its placement, ``off`` (m) across its axis: the
    alignment CheckAlignment measures, and the strut's middle where the arm holds it."""
    member = MISSION.member(member_id)
    width = ARS_X["end_effector"]["width"][member.kind]
    cfg = load_scene_config()
    before = [m.id for m in MISSION.members if m.kind in ("cross_frame", "vertical") and m.id != member_id]
    kw = dict(placed=set(before), bay=1, carrying=member.kind, width=width)
    free = build_scene(cfg, "ars_x", MISSION, contact=False, **kw)
    contact = build_scene(cfg, "ars_x", MISSION, contact=True, **kw)
    q = None
    for target in placement_targets(cfg, MISSION, member, "ars_x"):
        try:
            _, q = reach_target(free, contact, target, cfg.home("ars_x"), RESOLUTION)
            break
        except ValueError:  # this candidate is unusable: the ARS takes the next one too
            continue
    assert q is not None
    tool = cfg.kinematics("ars_x").forward(q)
    scene = scene_mod.Scene(out_dir=tmp_path)
    with scene:
        for placed in before:
            scene.stage_member(placed)
        for j, v in zip(names.arm_joints("ars_x"), q, strict=True):
            scene.set_joint_state(j, float(v))
        scene.set_joint_state(names.width_joint("ars_x"), width)
        mujoco.mj_forward(scene.model, scene.data)
        part = scene.part(scene.next_part(member.dispenser))
        middle = (tool @ part_in_tool(MISSION, member.kind))[:3, 3]
        axis = tool[:3, 0]
        along = part.ends["b"] - part.ends["a"]
        along /= np.linalg.norm(along)
        onto = np.column_stack([axis, *_perpendiculars(axis)])
        seated = onto @ np.column_stack([along, *_perpendiculars(along)]).T
        middle = middle + off * _perpendiculars(axis)[0]
        scene.place_part(part.name, middle - seated @ ((part.ends["a"] + part.ends["b"]) / 2), seated)
        site = load_config().raw["site"]
        level = site["build_level"] + MISSION.bay_height
        origin = np.asarray(site["base_origin"]) + np.array([0.0, 0.0, level])
        joints = [origin + np.asarray(p) for _, p in member.joints]
        pieces = expected_pieces(member.kind, joints, inspector.parts)
        seen = _pieces_seen(scene, inspector, "end_fitting", member.kind, pieces, segmenter=segmenter)
    return held_part_alignment(member.kind, pieces, seen, tool, inspector.tol, gate=0.1), middle


@pytest.mark.parametrize("member_id", ["bay1/vertical/x0_y1", "bay1/diagonal/face_x0"])
def test_a_held_strut_is_aligned_from_the_end_fittings_each_d405_sees(inspector, tmp_path, member_id):
    """A diagonal is held off its middle, the EE widened (config/ars/ars_x.yaml): D405 b, on the
    width slide, still sees the fitting at the far end."""
    result, middle = _held_strut(inspector, tmp_path, member_id)
    assert result.aligned and result.matched == 2, result
    assert result.position_error < 0.002
    assert np.linalg.norm(result.held[:3, 3] - middle) < 0.002


@pytest.mark.parametrize("off", [0.0, 0.008])
def test_a_held_vertical_is_measured_through_mask_rcnn_as_through_the_labels(inspector, tmp_path, off):
    """The shipped Mask R-CNN's fitting masks stop short where a fitting meets its tube; the
    depth's view of the fitting's end places it along its axis (tlt_vision.pose.axial_ends), so
    the part is measured where it is: in place, and 8 mm off it."""
    segmenter = MaskRcnnSegmenter.from_config(load_config())
    result, _ = _held_strut(inspector, tmp_path, "bay1/vertical/x0_y1", off, segmenter)
    assert result.matched == 2, result
    assert abs(result.position_error - off) < 0.002, result
    assert result.aligned == (off == 0.0)
