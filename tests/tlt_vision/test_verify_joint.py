"""The VerifyJoint service's handler: where it puts the hole from the caller's joint and the part
drawings, and what it answers for a frame with a seated head, a proud one, none, and for a
request it cannot judge (no frame, a camera not on an end effector, no depth, directions that
say nothing). The frame is made by hand: a fitting's face 0.30 m in front of the camera and a
rivet head's disc on it, its mask standing in for the segmenter's. Then on the twin: a shot of
each kind rendered by D405 a, the joint asked about where the ARS's model puts it (the mission's
joint where its planning scene stands the tower) and the gun's side from the end effector's pose,
the twin's rivet masks standing in for Mask R-CNN's."""

from __future__ import annotations

import logging
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from tlt_interfaces.srv import VerifyJoint
from tlt_sim.model import ik, names
from tlt_sim.model.config import REPO_ROOT
from tlt_sim.model.scenario import parse_scenario
from tlt_sim.model.scene import Scene

from tlt_ars.planning.world import load_scene_config, tower_origin
from tlt_common.geometry.transforms import frame_from_axes, pose_matrix
from tlt_common.mission.schema import load_mission
from tlt_vision.camera_frame import CameraFrame
from tlt_vision.camera_frames import NoFrame
from tlt_vision.detections import Detection
from tlt_vision.inspection.rivet_joint import RivetJointLimits
from tlt_vision.pointcloud import Intrinsics
from tlt_vision.services.verify_joint import VerifyJointHandler, hole_in_world

PARTS = {"corner_size": 0.05, "fitting_length": 0.05, "fitting_radius": 0.02}
K = Intrinsics(300.0, 300.0, 160.0, 120.0)
CAMERA = "ars_x/d405_a"
# The camera's optical frame is the world's; the member runs along x, the gun fired from -z (the
# camera's side), so the hole is 5 cm along and 2 cm out from the joint: straight ahead at 0.30 m.
JOINT, ALONG, OUTWARD = np.array([-0.05, 0.0, 0.32]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])


def _frame(head_depth: float | None, *, depth: bool = True) -> tuple[CameraFrame, list[Detection]]:
    v, u = np.mgrid[0:240, 0:320]
    image = np.full((240, 320), 0.30)
    disc = np.hypot(u - 160, v - 120) <= 5.5
    detections = []
    if head_depth is not None:
        image[disc] = head_depth
        detections.append(Detection("rivet", disc))
    detections.append(Detection("end_fitting", np.hypot(u - 160, v - 120) <= 30))
    images = {"depth": image} if depth else {}
    k = np.array([[K.fx, 0, K.cx], [0, K.fy, K.cy], [0, 0, 1]])
    return CameraFrame(CAMERA, 1.0, "d405_a_optical", K, k, images), detections


class _Frames:
    def __init__(self, frame: CameraFrame | None) -> None:
        self.frame = frame

    def camera(self, name: str) -> str:
        if name not in (CAMERA, "zed_1"):
            raise NoFrame(f"unknown camera {name!r}")
        return name

    def deadline(self) -> float:
        return float("inf")

    def grab(self, camera, streams, deadline) -> CameraFrame:
        if self.frame is None:
            raise NoFrame(f"no frame from {camera} in time")
        return self.frame


class _Detector:
    def __init__(self, detections: list[Detection]) -> None:
        self.detections = detections

    def streams(self) -> tuple[str, ...]:
        return ("depth", "labels")

    def detect(self, frame, doubtful=False) -> list[Detection]:
        return self.detections


def _handler(frame: CameraFrame | None, detections: list[Detection]) -> VerifyJointHandler:
    rig = SimpleNamespace(ee={CAMERA: None}, camera_pose=lambda camera, at: np.eye(4))
    return VerifyJointHandler(
        frames=_Frames(frame),
        detector=_Detector(detections),
        rig=rig,
        parts=PARTS,
        limits=RivetJointLimits(head_radius=0.006),
        clock=lambda: 1.0,
        logger=logging.getLogger("test"),
    )


def _ask(handler: VerifyJointHandler, camera: str = CAMERA, along=ALONG, outward=OUTWARD):
    request = VerifyJoint.Request(joint_id="bay1/vertical/x0_y0@bay1/x0_y0", camera=camera)
    request.joint.x, request.joint.y, request.joint.z = JOINT
    request.along.x, request.along.y, request.along.z = along
    request.outward.x, request.outward.y, request.outward.z = outward
    return handler(request, VerifyJoint.Response())


def test_the_hole_lies_half_a_corner_and_half_a_fitting_along_and_a_fitting_out():
    hole, out, along = hole_in_world(JOINT, 2 * ALONG, OUTWARD + 0.3 * ALONG, PARTS)
    np.testing.assert_allclose(hole, [0.0, 0.0, 0.30])
    np.testing.assert_allclose(out, OUTWARD)
    np.testing.assert_allclose(along, ALONG)
    with pytest.raises(ValueError, match="along the member"):
        hole_in_world(JOINT, ALONG, ALONG, PARTS)
    with pytest.raises(ValueError, match="zero"):
        hole_in_world(JOINT, np.zeros(3), OUTWARD, PARTS)


def test_a_seated_head_is_good_with_its_figures_and_its_place_in_the_world():
    response = _ask(_handler(*_frame(0.297)))
    assert response.verdict == VerifyJoint.Response.GOOD, response.reason
    assert abs(response.height) < 0.002 and abs(response.along_offset) < 0.002
    assert response.pixels > 50
    assert response.head.z == pytest.approx(0.297, abs=0.002)


def test_a_proud_head_is_unseated_and_a_missing_one_no_head():
    proud = _ask(_handler(*_frame(0.292)))
    assert proud.verdict == VerifyJoint.Response.UNSEATED, proud.reason
    assert proud.height == pytest.approx(0.005, abs=0.001)
    missing = _ask(_handler(*_frame(None)))
    assert missing.verdict == VerifyJoint.Response.NO_HEAD, missing.reason


def test_what_cannot_be_judged_says_why_and_never_passes():
    frame, detections = _frame(0.297)
    answers = {
        "no frame": _ask(_handler(None, detections)),
        "not an EE camera": _ask(_handler(frame, detections), camera="zed_1"),
        "unknown camera": _ask(_handler(frame, detections), camera="nowhere"),
        "no depth": _ask(_handler(*_frame(0.297, depth=False))),
        "gun along the member": _ask(_handler(frame, detections), outward=ALONG),
    }
    for case, response in answers.items():
        assert response.verdict == VerifyJoint.Response.CANNOT_JUDGE, case
        assert response.reason, case
    assert "in time" in answers["no frame"].reason
    assert "not an end-effector camera" in answers["not an EE camera"].reason
    assert "no depth" in answers["no depth"].reason


def test_an_unexpected_error_is_an_answer_that_cannot_judge():
    frame, _ = _frame(0.297)
    handler = _handler(frame, [])
    handler.detector = None  # any error inside the judgement
    response = _ask(handler)
    assert response.verdict == VerifyJoint.Response.CANNOT_JUDGE
    assert response.reason.startswith("vision error:")


# ----- on the twin -----
ARM, GUN, FEEDER = "ars_x", "a", "rivet_dispenser_x"
MEMBER, TWIN_JOINT = "bay1/vertical/x0_y0", "bay1/x0_y0"


def _arm_to(scene, position, rotation, point):
    waypoints = ik.plan(scene.model, scene.data.qpos, ARM, position, rotation, scene.ee_point(ARM, point))
    assert waypoints is not None, f"no way to {position}"
    scene.pose_arm(ARM, waypoints[-1])


def _load_gun(scene):
    pickup = scene.site_position(f"dispenser/{FEEDER}/pickup")
    for yaw in np.arange(8) * np.pi / 4:
        rotation = frame_from_axes([np.cos(yaw), np.sin(yaw), 0.0], [0.0, 0.0, -1.0])
        if ik.plan(scene.model, scene.data.qpos, ARM, pickup, rotation, scene.ee_point(ARM, f"gun_{GUN}")):
            _arm_to(scene, pickup, rotation, f"gun_{GUN}")
            assert scene.load_rivet(ARM, GUN)
            return
    raise AssertionError("no way to the feeder")


@pytest.fixture(scope="module")
def twin_shots(tmp_path_factory):
    """Each kind's shot at TWIN_JOINT as D405 a sees it, the ARS's geometry of the joint, and the
    frame's camera pose."""
    mission = load_mission(REPO_ROOT / "missions" / "one_bay.yaml")
    member = mission.member(MEMBER)
    origin = tower_origin(load_scene_config(), mission, member.bay)
    here = origin + np.asarray(dict(member.joints)[TWIN_JOINT], dtype=float)
    there = origin + np.asarray(next(p for k, p in member.joints if k != TWIN_JOINT), dtype=float)
    out = {}
    for kind in ("good", "proud_head", "no_rivet"):
        faults = (
            {}
            if kind == "good"
            else {"rivet_faults": [{"member": MEMBER, "joint": TWIN_JOINT, "kind": kind}]}
        )
        scenario = parse_scenario({"name": kind, "faults": faults}, mission)
        scene = Scene(mission=mission, scenario=scenario, out_dir=tmp_path_factory.mktemp(kind))
        scene.stage_bay(1, skip_rivets=((MEMBER, TWIN_JOINT),))
        _load_gun(scene)
        approach = frame_from_axes([0.0, 0.0, 1.0], [-0.3, 1.0, 0.0])
        _arm_to(scene, scene.truth.joint_position_world(TWIN_JOINT), approach, f"gun_{GUN}")
        scene.fire_rivet(ARM, GUN)
        gun_side = -scene.body_pose(names.ee_body(ARM))[1][:, 2]  # the tool's -z, as the ARS sends it
        shot = scene.render(names.d405_camera(ARM, GUN), 320, 240)
        out[kind] = (shot, here, there - here, gun_side)
        scene.close()
    return out


@pytest.mark.parametrize(
    ("kind", "verdict"), [("good", "good"), ("proud_head", "unseated"), ("no_rivet", "no_head")]
)
def test_the_twin_s_shots_are_judged_at_the_joint_the_ars_s_model_gives(twin_shots, kind, verdict):
    shot, joint, along, gun_side = twin_shots[kind]
    shown = shot.instances()
    rivets = [
        Detection("rivet", shot.mask(name))
        for name, cls in zip(shot.labels.instance_names, shot.labels.classes, strict=True)
        if cls == "rivet" and name in shown
    ]
    k = shot.intrinsics
    frame = CameraFrame(CAMERA, 1.0, "d405_a_optical", k, np.eye(3), {"depth": shot.depth})
    pose = pose_matrix(shot.position, shot.rotation)
    parts = yaml.safe_load((REPO_ROOT / "config" / "vision" / "parts.yaml").read_text())
    handler = VerifyJointHandler(
        frames=_Frames(frame),
        detector=_Detector(rivets),
        rig=SimpleNamespace(ee={CAMERA: None}, camera_pose=lambda camera, at: pose),
        parts=parts,
        limits=RivetJointLimits(head_radius=float(parts["rivet_radius"])),
        clock=lambda: 1.0,
        logger=logging.getLogger("test"),
    )
    request = VerifyJoint.Request(joint_id=f"{MEMBER}@{TWIN_JOINT}", camera=CAMERA)
    request.joint.x, request.joint.y, request.joint.z = joint
    request.along.x, request.along.y, request.along.z = along
    request.outward.x, request.outward.y, request.outward.z = gun_side
    response = handler(request, VerifyJoint.Response())
    assert response.verdict == verdict, response.reason
    if verdict != "no_head":
        head = np.array([response.head.x, response.head.y, response.head.z])
        assert np.linalg.norm(head - joint) < 0.06  # on the fitting at this joint, in the world
