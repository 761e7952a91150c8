"""A cross frame held by ARS X at its configured inspection pose, seen by the lifter ZED facing it.

The twin (``tlt_sim.model.Scene``) puts ARS X's arm at ``poses.inspection_cross_frame`` of
config/ars/ars_x.yaml, the camera mounts at the CRS's outward angle (0), and the dispenser's next
cross frame in the grasp the way the ARS holds it (middle of one side on the tool, the frame
extending along tool +y, as ``tlt_ars.planning.targets.cross_frame_targets`` takes it). The ZED
frame is rendered at the twin's run size and segmented by the twin's labels
(``segmentation_source.TwinLabels``, as the launch set runs vision); then the part inspection of
the vision node (:class:`tlt_vision.part_inspection.PartInspector`, the shipped weights) runs on it.

What the build relies on and this checks: the whole frame is in view and large, the part picked
out is the held frame only (not the lifter's top frame or the dispenser's stack in view), and its
C-3PO pose is certified and matches the twin's truth. The pose is collision-free in the ARS
planning scene with the frame held.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from tlt_ars.planning.world import build_scene, load_scene_config
from tlt_common.config_schema import load_yaml
from tlt_common.mission.schema import load_mission
from tlt_vision.camera_frames import CameraFrame
from tlt_vision.node_config import load_config
from tlt_vision.part_inspection import PartInspector
from tlt_vision.segmentation_source import TwinLabels

scene_mod = pytest.importorskip("tlt_sim.model.scene")
names = pytest.importorskip("tlt_sim.model.names")

ROOT = Path(__file__).resolve().parents[2]
ARS_X = load_yaml(ROOT / "config" / "ars" / "ars_x.yaml")
RUN = load_yaml(ROOT / "config" / "twin" / "run.yaml")
CAMERA = "zed_2"  # the lifter ZED on ARS X's side (zed_1 looks away from it at every hinge angle)


def _joints() -> np.ndarray:
    return np.array(ARS_X["poses"]["inspection_cross_frame"]["joints"], dtype=float)


@pytest.fixture(scope="module")
def presented(tmp_path_factory):
    """The rendered frame, the held part and the scene, with ARS X presenting the frame."""
    scene = scene_mod.Scene(out_dir=tmp_path_factory.mktemp("twin"))
    with scene:
        for j, v in zip(names.arm_joints("ars_x"), _joints(), strict=True):
            scene.set_joint_state(j, float(v))
        for i in range(2):
            scene.set_joint_state(names.camera_mount(i), 0.0)
        mujoco.mj_forward(scene.model, scene.data)
        part = scene.part(scene.next_part("cross_frame_dispenser"))
        centre, axis = scene.assembly.grasp_line("ars_x")
        tool = load_scene_config().kinematics("ars_x").forward(_joints())
        y = tool[:3, 1] - (tool[:3, 1] @ axis) * axis
        y /= np.linalg.norm(y)
        scene.place_part(
            part.name, centre - axis * part.length / 2, np.column_stack([axis, y, np.cross(axis, y)])
        )
        size = RUN["cameras"]["zed"]
        yield scene, part, scene.render(CAMERA, size["width"], size["height"])


def test_the_inspection_pose_is_collision_free_with_the_frame_held():
    cfg = load_scene_config()
    mission = load_mission(ROOT / "missions" / "one_bay.yaml")
    world = build_scene(cfg, "ars_x", mission, other_arm_q=cfg.home("ars_y"), carrying="cross_frame")
    assert not world.in_collision(_joints())


def test_the_whole_held_frame_is_in_view_and_large(presented):
    _, part, frame = presented
    seen = {k.rsplit("/", 1)[1]: n for k, n in frame.instances().items() if k.startswith(part.body + "/")}
    assert all(seen.get(f"side_{i}", 0) >= 500 for i in range(4)), seen
    assert all(seen.get(f"corner_{i}", 0) >= 80 for i in range(4)), seen


def test_the_held_frame_alone_is_inspected_and_its_pose_is_certified(presented):
    scene, part, frame = presented
    config = load_config()
    inspector = PartInspector(config, scene.mission)
    labels = TwinLabels(lambda: (frame.labels.instance_names, frame.labels.classes))
    camera_frame = CameraFrame(
        CAMERA,
        0.0,
        f"{CAMERA}_optical",
        frame.intrinsics,
        frame.intrinsics.matrix,
        {"depth": frame.depth, "segmentation": frame.segmentation, "rgb": frame.rgb},
    )
    detections = labels.detect(camera_frame)
    picked = inspector.select("cross_frame", detections, frame.depth, frame.intrinsics)
    assert picked and all(d.object_id.startswith(part.body + "/") for d in picked), [
        d.object_id for d in picked
    ]
    others = {d.object_id for d in detections if d.object_class == "cross_frame"} - {
        d.object_id for d in picked
    }
    assert others, "other cross frames are in view (the lifter's top frame, the dispenser stack)"

    report, obs = inspector.inspect(
        "bay1/cross_frame", "cross_frame", detections, frame.depth, frame.intrinsics, frame.rgb
    )
    frames = [o.estimate for o in obs if o.object_class == "cross_frame" and o.estimate is not None]
    assert len(frames) == 1
    est = frames[0]
    assert est.certified, est.certificate.reason
    assert not any(r.startswith("cross_frame") for r in report.reasons), report.reasons
    # The certified pose is the held frame's: its centre within 1 cm of the twin's truth.
    pos, rot = scene.body_pose(part.body)
    hw = part.length / 2
    truth = frame.rotation.T @ (pos + rot @ np.array([hw, hw, 0.0]) - frame.position)
    assert np.linalg.norm(est.translation - truth) < 0.01, (est.translation, truth)
