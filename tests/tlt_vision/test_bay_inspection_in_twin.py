"""InspectBay on the twin: bay 1 built, both lifter ZEDs turned inward as Test Bay turns them.

The twin stages every member of bay 1 where the mission has it and turns the camera mounts to the
CRS's inward angles (config/crs/crs.yaml); both ZEDs render at the twin's run size. Vision's bay
pipeline (the twin's segmentation, C-3PO on each corner joint) finds the corner joints, placed in
the world by vision's own camera rig (config/vision/node.yaml at those hinge angles), and
:func:`tlt_vision.inspection.inspect_bay` judges them against the mission's joints where the tower
stands while bay 1 is built, as the vision node does. The views also show the dispensers' stacked
cross frames: a whole run once matched those and failed a good bay.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest

from tlt_common.config_schema import load_yaml
from tlt_common.mission.schema import load_mission
from tlt_vision.detections import detections_near
from tlt_vision.frames import CameraRig
from tlt_vision.inspection import Observation, bay_joints, corner_joint_prior, inspect_bay
from tlt_vision.node_config import load_config
from tlt_vision.part_inspection import PartInspector
from tlt_vision.segmentation_source import TwinLabels

scene_mod = pytest.importorskip("tlt_sim.model.scene")
names = pytest.importorskip("tlt_sim.model.names")

ROOT = Path(__file__).resolve().parents[2]
ZED = load_yaml(ROOT / "config" / "twin" / "run.yaml")["cameras"]["zed"]
MOUNTS = load_yaml(ROOT / "config" / "crs" / "crs.yaml")["camera_mounts"]
MISSION_FILE = ROOT / "missions" / "one_bay.yaml"
MISSION = load_mission(MISSION_FILE)
CONFIG = load_config()


def _seen(tmp_path: Path, shift_bottom_frame: float = 0.0) -> list[Observation]:
    """Corner joint observations (world) in both inward ZED frames of the staged bay 1."""
    inspector, rig = PartInspector(CONFIG, MISSION), CameraRig(CONFIG)
    hinges = dict(zip(MOUNTS["joints"], MOUNTS["inward"], strict=True))
    out: list[Observation] = []
    with scene_mod.Scene(mission=MISSION_FILE, out_dir=tmp_path) as scene:
        frame_part = scene.stage_bay(1)["bay1/cross_frame"]
        if shift_bottom_frame:
            body = scene.data.body(scene.part(frame_part).body)
            moved = body.xpos + np.array([shift_bottom_frame, 0.0, 0.0])
            scene.place_part(frame_part, moved, body.xmat.reshape(3, 3))
        for joint, angle in hinges.items():
            scene.set_joint_state(joint, float(angle))
        mujoco.mj_forward(scene.model, scene.data)
        for camera in CONFIG.raw["bay_cameras"]:
            f = scene.render(camera, ZED["width"], ZED["height"])
            found = [d for d in TwinLabels.detect_render(f, camera) if d.object_class == "corner_joint"]
            pose = rig.pose_from_joints(camera, hinges)
            # As the node does: only the joints within the gate's reach of a place get a pose.
            radius = CONFIG.raw["held_piece_gate"] + inspector.estimators["corner_joint"].model.diameter / 2
            places = np.array(list(_expected().values()))
            found = detections_near(found, f.depth, f.intrinsics, pose, places, radius)
            # As the node does: each joint's fit also starts from its place.
            prior = corner_joint_prior(places, pose)
            for o in inspector.observe("bay", found, f.depth, f.intrinsics, f.rgb, prior):
                if o.estimate is not None:
                    world = pose[:3, :3] @ o.estimate.translation + pose[:3, 3]
                    o = replace(o, estimate=replace(o.estimate, translation=world))
                out.append(o)
    return out


def _expected() -> dict[str, np.ndarray]:
    """Bay 1's corner joints in the world while it is built
    (:func:`tlt_vision.services.world.tower_origin`)."""
    site = CONFIG.raw["site"]
    origin = np.asarray(site["base_origin"]) + np.array([0.0, 0.0, site["build_level"] + MISSION.bay_height])
    return {k: origin + np.asarray(p) for k, p in bay_joints(MISSION, 1).items()}


def _inspect(seen: list[Observation]):
    expected = _expected()
    tol = PartInspector(CONFIG, MISSION).tol
    gate, least = CONFIG.raw["held_piece_gate"], CONFIG.raw["bay_min_corner_joints"]
    return inspect_bay(1, expected, seen, tol, gate, least)


def test_a_built_bay_passes_on_its_own_corner_joints_from_both_frames(tmp_path):
    report = _inspect(_seen(tmp_path))
    assert report.passed, report.reasons


def test_a_bay_whose_bottom_frame_stands_2_cm_off_fails(tmp_path):
    report = _inspect(_seen(tmp_path, shift_bottom_frame=0.02))
    assert not report.passed
    assert any(r.startswith("corner joint bay1/") and "off by" in r for r in report.reasons), report.reasons
