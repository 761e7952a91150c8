"""Against the twin's renders: its parts fit the CAD models, and inspection catches its defects.

Frames come from the MuJoCo twin (sim/tlt_sim, scenario ``defective_parts``: the first vertical of
ARS X's dispenser lacks end fitting b, the second has a tube bent by 8 degrees). Masks are the
twin's ground-truth segmentation, poses its geoms' true poses (a bent tube has no true straight
pose, so its pose is the corrector's best fit from the nominal one): this checks the geometry,
intrinsics, depth convention, certificate thresholds and inspection logic end to end, without a
trained network.
"""

from pathlib import Path

import pytest
import torch

from tlt_vision.cad.models import load_parts, models_for_mission, strut_layout
from tlt_vision.detections import Detection, merge_instances
from tlt_vision.inspection import Observation, Tolerances, inspect_cross_frame, inspect_strut
from tlt_vision.ops.registration import transform
from tlt_vision.pointcloud import masked_point_cloud
from tlt_vision.pose.certificate import certify
from tlt_vision.pose.corrector import correct, model_frame
from tlt_vision.pose.estimator import PoseEstimate

scene_mod = pytest.importorskip("tlt_sim.model.scene")
names = pytest.importorskip("tlt_sim.model.names")

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "config" / "twin" / "scenarios" / "defective_parts.yaml"
PARTS = load_parts()


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    # Set-up installs OSMesa, so the twin renders wherever the tests run; a failure here is real.
    scene = scene_mod.Scene(out_dir=tmp_path_factory.mktemp("twin"), scenario=SCENARIO)
    with scene:
        yield scene, models_for_mission(scene.mission)


def _pose_in_camera(frame, pos_w, rot_w):
    return frame.rotation.T @ rot_w, frame.rotation.T @ (pos_w - frame.position)


def _estimate(model, cloud, rot, t, threshold, fit=False):
    o = torch.tensor(cloud, dtype=torch.float32)
    kp_model = torch.tensor(model.keypoints, dtype=torch.float32)
    r, tt = torch.tensor(rot, dtype=torch.float32), torch.tensor(t, dtype=torch.float32)
    if fit:
        res = correct(o[None], transform(kp_model, r, tt)[None], model.surface, kp_model, model.diameter / 2)
        r, tt = res.rotation[0], res.translation[0]
    dist = model.surface(model_frame(o[None], r[None], tt[None]))[0]
    cert = certify(o, dist, transform(kp_model, r, tt), model.visibility, threshold)
    kp = transform(kp_model, r, tt).numpy()
    return PoseEstimate(
        model.object_class, model.name, r.double().numpy(), tt.double().numpy(), kp, cert, len(o), 0.0
    )


def _observe(scene, models, part, bent=False):
    """Observations of a vertical strut held 0.9 m in front of ZED 1."""
    scene.reset()
    camera = names.zed_camera(0)
    body = scene.part(part).body
    scene.place_in_view(part, camera, 0.9)
    frame = scene.render(camera, 320, 240)
    thresholds = scene.mission.inspection["chamfer_thresholds"]
    length = scene.mission.strut_lengths["vertical"]
    observations = []
    for inst in sorted(k for k in frame.instances() if k.startswith(body + "/")):
        cls = frame.class_of(inst)
        model = models["strut_tube/vertical" if cls == "strut_tube" else cls]
        cloud = masked_point_cloud(frame.mask(inst), frame.depth, frame.intrinsics, min_points=16)
        assert cloud.ok, cloud.reason
        if cls == "strut_tube" and bent:
            pos, rot = scene.body_pose(body)  # nominal straight tube in the strut's frame
            rot_c, t_c = _pose_in_camera(
                frame, pos + rot @ [0.0, 0.0, strut_layout(length, PARTS)["tube_centre"]], rot
            )
            e = _estimate(model, cloud.points, rot_c, t_c, thresholds[cls], fit=True)
        else:
            g = scene.model.geom(inst).id
            rot_c, t_c = _pose_in_camera(
                frame, scene.data.geom_xpos[g], scene.data.geom_xmat[g].reshape(3, 3)
            )
            e = _estimate(model, cloud.points, rot_c, t_c, thresholds[cls])
        observations.append(Observation(cls, e, object_id=inst))
    return observations, length


def test_true_poses_of_rendered_parts_are_certified_and_a_shifted_one_is_not(twin):
    scene, models = twin
    observations, _ = _observe(scene, models, "vertical_dispenser_x/2")
    assert sorted(o.object_class for o in observations) == ["end_fitting", "end_fitting", "strut_tube"]
    for o in observations:
        assert o.estimate.certified, (o.object_id, o.estimate.certificate.reason)
    tube = next(o for o in observations if o.object_class == "strut_tube")
    frame = scene.render(names.zed_camera(0), 320, 240)
    points = masked_point_cloud(frame.mask(tube.object_id), frame.depth, frame.intrinsics).points
    e = tube.estimate
    shifted = e.translation + e.rotation[:, 0] * 0.02  # 2 cm sideways
    wrong = _estimate(
        models["strut_tube/vertical"], points, e.rotation, shifted, e.certificate.chamfer_threshold
    )
    assert not wrong.certified and "not observably correct" in wrong.certificate.reason


def test_inspection_of_the_twins_struts(twin):
    scene, models = twin
    tol = Tolerances.from_mission(scene.mission)
    good, length = _observe(scene, models, "vertical_dispenser_x/2")
    rep = inspect_strut("good", "vertical", length, good, PARTS, tol)
    assert rep.passed, rep.reasons
    missing, _ = _observe(scene, models, "vertical_dispenser_x/0")
    rep = inspect_strut("missing", "vertical", length, missing, PARTS, tol)
    assert not rep.passed and len(rep.reasons) == 1
    assert rep.reasons[0].startswith("missing end fitting: 1 of 2 found")
    bent, _ = _observe(scene, models, "vertical_dispenser_x/1", bent=True)
    rep = inspect_strut("bent", "vertical", length, bent, PARTS, tol)
    assert not rep.passed
    assert any(r.startswith("bent tube") for r in rep.reasons), rep.reasons


def test_cross_frame_from_the_twin_passes_and_a_missing_corner_fails(twin):
    scene, models = twin
    scene.reset()
    camera = names.zed_camera(0)
    part = "cross_frame_dispenser/0"
    body = scene.part(part).body
    # Facing the camera 1 m ahead, shifted down and right clear of the camera mount's own arm.
    cam_pos, cam_rot = scene.camera_pose(camera)
    w = scene.mission.bay_width
    centre = cam_pos + cam_rot @ [0.1, 0.1, 1.0]
    scene.place_part(part, centre - (cam_rot[:, 0] + cam_rot[:, 1]) * w / 2, cam_rot)
    frame = scene.render(camera, 640, 480)  # a corner joint is 17 px wide at 1 m
    thresholds = scene.mission.inspection["chamfer_thresholds"]
    detections = [
        Detection(frame.class_of(inst), frame.mask(inst), 1.0, inst)
        for inst in frame.instances()
        if inst.startswith(body + "/")
    ]
    # The twin labels each side as an instance; the pipeline merges them into one cross frame.
    assert sum(d.object_class == "cross_frame" for d in detections) == 4
    merged = merge_instances(detections, ["cross_frame"])
    observations = []
    pos, rot = scene.body_pose(body)  # frame corners at (0, 0) .. (w, w) in the body frame
    for d in merged:
        cloud = masked_point_cloud(d.mask, frame.depth, frame.intrinsics, min_points=16)
        assert cloud.ok, (d.object_id, cloud.reason)
        if d.object_class == "cross_frame":
            rot_c, t_c = _pose_in_camera(frame, pos + rot @ [w / 2, w / 2, 0.0], rot)
        else:
            g = scene.model.geom(d.object_id).id
            rot_c, t_c = _pose_in_camera(
                frame, scene.data.geom_xpos[g], scene.data.geom_xmat[g].reshape(3, 3)
            )
        model = models[d.object_class]
        e = _estimate(model, cloud.points, rot_c, t_c, thresholds[d.object_class])
        assert e.certified, (d.object_id, e.certificate.reason)
        observations.append(Observation(d.object_class, e, object_id=d.object_id))
    tol = Tolerances.from_mission(scene.mission)
    rep = inspect_cross_frame("cross_frame", w, observations, tol)
    assert rep.passed, rep.reasons
    without = [o for o in observations if not o.object_id.endswith("/corner_2")]
    rep = inspect_cross_frame("cross_frame", w, without, tol)
    assert (
        not rep.passed
        and len(rep.reasons) == 1
        and rep.reasons[0].startswith("missing corner joint at corner")
    )
