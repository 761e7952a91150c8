"""The transform tree places every camera where the twin has it, from the drivers' joint states."""

import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.scene import Scene

from tlt_vision.frames import (
    CameraRig,
    FrameUnavailable,
    JointStates,
    arm_joint_names,
    grasp_joint_names,
    width_joint_name,
)
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


def test_the_rig_is_ready_once_every_joint_its_cameras_and_end_effectors_need_was_heard():
    """Vision says ready (the CRS refuses Start until it does) only when no request can meet "no
    joint state for ur_x_shoulder_pan_joint yet": every camera's joints and each end effector's."""
    joints = JointStates()
    rig = CameraRig(load_config(), joints)
    needed = rig.needed_joints()
    assert rig.arms == ["ars_x", "ars_y"]
    for arm in rig.arms:
        end_effector = {width_joint_name(arm), *grasp_joint_names(arm).values()}
        assert set(arm_joint_names(arm)) | end_effector <= set(needed)
    assert {camera.joint for camera in rig.lifter.values()} <= set(needed)
    assert rig.not_ready() == f"no joint state yet for {', '.join(needed[:3])} and {len(needed) - 3} more"
    heard = [n for n in needed if not n.startswith("ur_y_")]
    joints.update(heard, [0.0] * len(heard), stamp=1.0)
    ur_y = arm_joint_names("ars_y")
    assert rig.not_ready() == f"no joint state yet for {', '.join(ur_y[:3])} and 3 more"
    joints.update(ur_y, [0.0] * 6, stamp=1.0)
    assert rig.not_ready() == ""


def test_a_camera_is_placed_where_it_was_when_its_frame_was_taken():
    """The mount turns while a frame is on its way: the frame, stamped 5.1 s, is read after a
    state of 5.2 s came in, and is placed by the mount's angle at 5.1 s (between its states of 5.0
    and 5.2 s), not by the latest. A time before every state kept takes the oldest, within the
    age limit; :meth:`JointStates.latest` is the newest whatever the time."""
    joints = JointStates()
    rig = CameraRig(load_config(), joints)
    joints.update(["camera_mount_1"], [0.0], stamp=5.0)
    joints.update(["camera_mount_1"], [0.2], stamp=5.2)
    joints.update(["camera_mount_1"], [0.4], stamp=5.4)
    halfway = rig.pose_from_joints("zed_1", {"camera_mount_1": 0.1})
    assert np.abs(rig.camera_pose("zed_1", at=5.1) - halfway).max() < 1e-12
    assert joints.get(["camera_mount_1"], 5.4, 0.1) == [0.4]
    assert joints.get(["camera_mount_1"], 4.5, 1.0) == [0.0]
    assert joints.latest(["camera_mount_1"]) == [0.4]
    with pytest.raises(FrameUnavailable, match="no joint state for camera_mount_0"):
        joints.latest(["camera_mount_0"])
    # States that arrive out of order are kept in order; one at a stamp already held replaces it.
    joints.update(["camera_mount_1"], [0.3], stamp=5.3)
    joints.update(["camera_mount_1"], [0.25], stamp=5.3)
    assert joints.get(["camera_mount_1"], 5.35, 0.1) == pytest.approx([0.325])


def test_joint_states_keep_a_bounded_history():
    joints = JointStates(history=4)
    for k in range(10):
        joints.update(["j"], [float(k)], stamp=float(k))
    assert joints.get(["j"], 6.5, 0.5) == [6.5]
    with pytest.raises(FrameUnavailable, match=r"j is 1\.00 s from the frame"):
        joints.get(["j"], 5.0, 0.5)  # state 5 was dropped: the oldest kept is 6
    # Nor is a position guessed across a silence of the driver longer than the age limit.
    joints.update(["j"], [20.0], stamp=20.0)
    with pytest.raises(FrameUnavailable, match=r"j is 5\.00 s from the frame"):
        joints.get(["j"], 14.0, 1.0)
    assert joints.get(["j"], 19.5, 1.0) == [20.0] and joints.get(["j"], 9.5, 1.0) == [9.0]
