"""The coarse dispenser poses of config/ars/*.yaml (§V.C.3): from each, the arm stands clear of
everything the planner knows, and the end effector's camera sees that dispenser's AprilTag in the
twin, so the fine approach (LocateTag) can begin where the coarse approach ends."""

from __future__ import annotations

import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.scene import Scene

from tlt_ars.config import default_config_path
from tlt_ars.planning.world import build_scene, load_scene_config
from tlt_common.config_schema import load_yaml
from tlt_common.mission.schema import load_mission
from tlt_vision.apriltag import TagConfig, TagLocator

MISSION = "missions/one_bay.yaml"  # every mission shares the dispenser layout
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    with Scene(mission=MISSION, out_dir=tmp_path_factory.mktemp("model")) as scene:
        yield scene


@pytest.mark.parametrize("ars", ["ars_x", "ars_y"])
def test_from_each_coarse_pose_the_ee_camera_sees_the_dispensers_tag(twin, ars):
    mission = load_mission(MISSION)
    tag_ids = {name: i for i, name in enumerate(mission.dispensers)}
    collision = build_scene(load_scene_config(), ars, mission, other_arm_q=HOME)
    locator = TagLocator(TagConfig.load())
    poses = load_yaml(default_config_path(ars))["poses"]["dispensers"]
    assert poses
    for dispenser, pose in poses.items():
        q = np.array(pose["joints"])
        assert not collision.in_collision(q), f"{ars} coarse pose for {dispenser} collides"
        for joint, value in zip(names.arm_joints(ars), q, strict=True):
            twin.set_joint_state(joint, value)
        twin.step(1)
        frame = twin.render(f"{ars}/d405_a", 320, 240)
        i = frame.intrinsics
        k = np.array([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])
        seen = [t.tag_id for t in locator.detect(frame.rgb, k)]
        assert tag_ids[dispenser] in seen, f"{ars} at its {dispenser} pose sees tags {seen}"
