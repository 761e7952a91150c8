"""The transform tree places every camera where the twin has it, from the drivers' joint states."""

import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.scene import Scene

from tlt_vision.frames import CameraRig, FrameUnavailable, JointStates, arm_joint_names, width_joint_name
from tlt_vision.node_config import load_config


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    with Scene(out_dir=tmp_path_factory.mktemp("frames")) as s:
        yield s


def _driver_positions(scene: Scene) -> dict[str, float]:
    """Joint positions under the drivers' names, read from the model (what the drivers publish)."""
    out = {names.camera_mount(i): scene.position(names.camera_mount(i)) for i in range(2)}
    for arm in names.ARMS:
        out.update(zip(arm_joint_names(arm), [scene.position(j) for j in names.arm_joints(arm)], strict=True))
        out[width_joint_name(arm)] = scene.position(names.width_joint(arm))
    return out


@pytest.mark.parametrize("pose_index", [0, 1])
def test_every_camera_pose_matches_the_twin(scene, pose_index):
    rng = np.random.default_rng(pose_index)
    for i in range(2):
        scene.set_joint_state(names.camera_mount(i), float(rng.uniform(-1.2, 1.2)))
    for arm in names.ARMS:
        for j in names.arm_joints(arm):
            scene.set_joint_state(j, float(rng.uniform(-2.5, 2.5)))
        scene.set_joint_state(names.width_joint(arm), float(rng.uniform(0.0, 0.3)))
    rig = CameraRig(load_config())
    positions = _driver_positions(scene)
    for camera in names.cameras():
        got = rig.pose_from_joints(camera, positions)
        pos, rot = scene.camera_pose(camera)
        assert np.linalg.norm(got[:3, 3] - pos) < 1e-6, camera
        assert np.abs(got[:3, :3] - rot).max() < 1e-6, camera


def test_camera_pose_needs_fresh_joint_states():
    joints = JointStates()
    rig = CameraRig(load_config(), joints)
    with pytest.raises(FrameUnavailable, match="no joint state for camera_mount_1"):
        rig.camera_pose("zed_1", at=10.0)
    joints.update(["camera_mount_1"], [0.3], stamp=5.0)
    with pytest.raises(FrameUnavailable, match=r"camera_mount_1 is 5.00 s from the frame"):
        rig.camera_pose("zed_1", at=10.0)
    assert rig.camera_pose("zed_1", at=5.5).shape == (4, 4)
    with pytest.raises(FrameUnavailable, match="unknown camera"):
        rig.camera_pose("zed_9", at=5.0)
