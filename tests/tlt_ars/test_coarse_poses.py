"""The coarse dispenser poses of config/ars/*.yaml (§V.C.3): from each, the arm stands clear of
everything the planner knows, and the end effector's camera sees that dispenser's AprilTag in the
twin well enough for the fine approach (LocateTag) to begin where the coarse approach ends: found
at the twin's frame size and at twice it, well inside the image (a tag at the border is found one
time and missed the next), and located to millimetres against the twin's ground truth. The same
holds in the two-bay mission, whose fuller racks carry their tags higher, once each pose has
followed its tag (tlt_ars.planning.coarse_pose_transfer)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from tlt_sim.model import names
from tlt_sim.model.scene import Scene
from tlt_tools.coarse_pose_search import Setup

from tlt_ars.config import default_config_path
from tlt_ars.planning.coarse_pose_transfer import NoCoarsePose, follow_tags
from tlt_ars.planning.world import build_scene, load_scene_config
from tlt_common.config_schema import load_yaml
from tlt_common.geometry.transforms import pose_matrix
from tlt_common.mission.schema import load_mission
from tlt_vision.apriltag import TagConfig, TagLocator, dispenser_tag_ids

MISSION = "missions/one_bay.yaml"  # the poses' dispensers_mission; every mission shares the layout
TWO_BAY = "missions/two_bay.yaml"  # fuller racks, their tags higher
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
SIZES = ((320, 240), (640, 480))  # the twin's D405 frames (config/twin/run.yaml), and twice that
MARGIN = 0.15  # each detected corner at least this fraction of the image size from every border
POSITION_TOLERANCE = 0.003  # m
ANGLE_TOLERANCE_DEG = 1.5
ARS_DISPENSERS = [
    (ars, dispenser)
    for ars in ("ars_x", "ars_y")
    for dispenser in load_yaml(default_config_path(ars))["poses"]["dispensers"]
]


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    with Scene(mission=MISSION, out_dir=tmp_path_factory.mktemp("model")) as scene:
        yield scene


@pytest.fixture(scope="module")
def mission():
    return load_mission(MISSION)


@pytest.fixture(scope="module")
def locator():
    return TagLocator(TagConfig.load())


@pytest.fixture(scope="module")
def collision(mission):
    cfg = load_scene_config()
    return {ars: build_scene(cfg, ars, mission, other_arm_q=HOME) for ars in ("ars_x", "ars_y")}


def coarse_pose(ars: str, dispenser: str) -> np.ndarray:
    return np.array(load_yaml(default_config_path(ars))["poses"]["dispensers"][dispenser]["joints"])


def tag_truth(twin: Scene, dispenser: str) -> np.ndarray:
    """The tag's frame in the world as the twin built it: at the tag's site on its face, turned
    as its dispenser (the tag frame is the dispenser's, config/vision/node.yaml tag_mount.rpy)."""
    _, rotation = twin.body_pose(f"dispenser/{dispenser}")
    return pose_matrix(twin.site_position(f"dispenser/{dispenser}/tag"), rotation)


def test_every_dispenser_each_ars_uses_has_a_coarse_pose(mission):
    assert {d for _, d in ARS_DISPENSERS} == set(mission.dispensers)


@pytest.mark.parametrize(("ars", "dispenser"), ARS_DISPENSERS)
def test_coarse_pose_is_free_and_within_the_limits(collision, ars, dispenser):
    q = coarse_pose(ars, dispenser)
    lower, upper = load_scene_config().joint_limits(ars)
    assert np.all(q >= lower) and np.all(q <= upper), f"{ars} {dispenser}: {q} outside the limits"
    assert not collision[ars].in_collision(q), f"{ars} coarse pose for {dispenser} collides"


@pytest.mark.parametrize(("ars", "dispenser"), ARS_DISPENSERS)
def test_from_the_coarse_pose_the_ee_camera_locates_the_tag_well(twin, mission, locator, ars, dispenser):
    assert_locates_well(twin, mission, locator, ars, dispenser, coarse_pose(ars, dispenser))


def assert_locates_well(twin, mission, locator, ars: str, dispenser: str, q: np.ndarray) -> None:
    for joint, value in zip(names.arm_joints(ars), q, strict=True):
        twin.set_joint_state(joint, value)
    twin.step(1)
    camera = f"{ars}/d405_a"
    position, rotation = twin.camera_pose(camera)
    cam = pose_matrix(position, rotation)
    truth = tag_truth(twin, dispenser)
    tag_id = dispenser_tag_ids(list(mission.dispensers))[dispenser]
    for w, h in SIZES:
        frame = twin.render(camera, w, h, depth=False, segmentation=False)
        i = frame.intrinsics
        k = np.array([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])
        result = locator.locate(frame.rgb, tag_id, k)
        assert result.found, f"{ars} at its {dispenser} pose, {w}x{h}: {result.reason}"
        c = result.pose.corners
        margin = min(c[:, 0].min() / w, c[:, 1].min() / h, 1 - c[:, 0].max() / w, 1 - c[:, 1].max() / h)
        assert margin >= MARGIN, f"{ars} {dispenser} {w}x{h}: tag {margin:.2f} of the image from a border"
        seen = cam @ pose_matrix(result.pose.translation, result.pose.rotation)
        error = np.linalg.norm(seen[:3, 3] - truth[:3, 3])
        rel = seen[:3, :3].T @ truth[:3, :3]
        angle = np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1.0, 1.0)))
        assert error <= POSITION_TOLERANCE, f"{ars} {dispenser} {w}x{h}: tag {1000 * error:.1f} mm off"
        assert angle <= ANGLE_TOLERANCE_DEG, f"{ars} {dispenser} {w}x{h}: tag {angle:.2f} deg off"


@pytest.mark.parametrize("dispenser", ["cross_frame_dispenser", "rivet_dispenser_x", "vertical_dispenser_y"])
def test_the_search_places_each_tag_where_the_twin_has_it(twin, dispenser):
    """coarse_pose_search's tag rule (the vision's LocateTag tag_mount) against the twin's model."""
    setup = Setup.load(MISSION)
    truth = tag_truth(twin, dispenser)
    mine = setup.tag_pose(dispenser)
    assert np.allclose(mine[:3, 3], truth[:3, 3], atol=1e-6)
    assert np.allclose(mine[:3, :3], truth[:3, :3], atol=1e-9)


@pytest.fixture(scope="module")
def two_bay_twin(tmp_path_factory):
    with Scene(mission=TWO_BAY, out_dir=tmp_path_factory.mktemp("model_two_bay")) as scene:
        yield scene


@pytest.fixture(scope="module")
def two_bay_poses():
    scene = load_scene_config()
    poses = {a: {d: coarse_pose(a, d) for b, d in ARS_DISPENSERS if b == a} for a in ("ars_x", "ars_y")}
    return {ars: follow_tags(poses[ars], ars, MISSION, TWO_BAY, scene) for ars in poses}


@pytest.mark.parametrize(("ars", "dispenser"), ARS_DISPENSERS)
def test_in_the_two_bay_mission_each_pose_follows_its_tag_and_still_sees_it(
    two_bay_twin, two_bay_poses, locator, ars, dispenser
):
    q = two_bay_poses[ars][dispenser]
    before, after = Setup.load(MISSION).tag_pose(dispenser), Setup.load(TWO_BAY).tag_pose(dispenser)
    if dispenser.startswith("rivet"):  # a feeder's tag stands at a fixed height: the pose is kept
        assert np.allclose(before, after) and np.array_equal(q, coarse_pose(ars, dispenser))
    else:
        assert after[2, 3] > before[2, 3] + 0.05  # the fuller rack's tag is higher
    lower, upper = load_scene_config().joint_limits(ars)
    assert np.all(q >= lower) and np.all(q <= upper)
    cfg = load_scene_config()
    assert not build_scene(cfg, ars, load_mission(TWO_BAY), other_arm_q=HOME).in_collision(q)
    assert_locates_well(two_bay_twin, load_mission(TWO_BAY), locator, ars, dispenser, q)


def test_a_pose_that_cannot_follow_its_tag_is_refused_naming_the_dispenser(tmp_path):
    """A vertical rack filled with 40 struts lifts its tag out of the arm's reach."""
    doc = load_yaml(TWO_BAY)
    (rack,) = [d for d in doc["dispensers"] if d["name"] == "vertical_dispenser_x"]
    rack["count"] = 40
    tall = tmp_path / "tall.yaml"
    tall.write_text(yaml.safe_dump(doc))
    poses = {"vertical_dispenser_x": coarse_pose("ars_x", "vertical_dispenser_x")}
    with pytest.raises(NoCoarsePose, match="vertical_dispenser_x"):
        follow_tags(poses, "ars_x", MISSION, tall, load_scene_config())
