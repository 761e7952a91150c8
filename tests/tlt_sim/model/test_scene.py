"""The scene: the model compiles, MuJoCo's errors name the file, and every mechanism moves."""

import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.scene import ModelCompileError, compile_model

from tlt_common.geometry import ur10e


def test_model_compiles_with_every_named_joint_actuator_and_camera(scene):
    m = scene.model
    for joint in names.all_actuated_joints():
        assert m.joint(joint).id >= 0 and m.actuator(joint).id >= 0
    for cam in names.cameras():
        assert m.camera(cam).id >= 0
    assert sorted(scene.servos.joints) == sorted(names.all_actuated_joints())
    assert scene.truth.active_constraints("top/") == [f"top/{i}/payload" for i in range(4)]


def test_compile_error_carries_mujocos_message_and_the_file(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text('<mujoco><worldbody><geom type="box" size="1"/></worldbody></mujoco>')
    with pytest.raises(ModelCompileError) as err:
        compile_model(bad)
    assert err.value.path == bad
    assert "size" in err.value.message.lower()
    assert str(bad) in str(err.value)


def test_arm_chain_matches_the_published_dh_kinematics(scene):
    q = [0.3, -1.1, 1.4, -0.7, 0.9, 0.2]
    for joint, value in zip(names.arm_joints("ars_y"), q, strict=True):
        scene.set_joint_state(joint, value)
    base_pos, base_rot = scene.body_pose("ars_y/base")
    pos, rot = scene.body_pose(names.ee_body("ars_y"))
    expected = ur10e.flange(q)
    assert np.allclose(base_rot.T @ (pos - base_pos), expected[:3, 3], atol=1e-9)
    assert np.allclose(base_rot.T @ rot, expected[:3, :3], atol=1e-9)


@pytest.mark.parametrize(
    ("joint", "target"),
    [
        (names.lifter_joint(2), 0.2),
        (names.active_gripper(1), 0.8),
        (names.top_gripper(3), 0.005),
        (names.camera_mount(0), 1.0),
        (names.arm_joint("ars_x", 0), 0.4),
        (names.arm_joint("ars_y", 2), 1.2),
        (names.grasp_joint("ars_y", "b"), 1.4),
        (names.width_joint("ars_x"), 0.31),
    ],
)
def test_joint_moves_to_a_commanded_position_no_faster_than_rated(scene, joint, target):
    start = scene.position(joint)
    vmax = scene.max_velocity(joint)
    scene.command_position(joint, target)
    scene.advance(0.1)
    assert abs(scene.position(joint) - start) <= vmax * 0.1 + 0.01
    assert scene.run_until(
        lambda: abs(scene.position(joint) - target) < 2e-3, abs(target - start) / vmax + 2.0
    )


def test_velocity_command_drives_until_held(scene):
    joint = names.lifter_joint(0)
    start = scene.position(joint)
    scene.command_velocity(joint, 0.04)
    scene.advance(1.0)
    assert scene.position(joint) - start == pytest.approx(0.04, abs=3e-3)
    assert scene.velocity(joint) == pytest.approx(0.04, abs=5e-3)
    scene.hold(joint)
    held = scene.servos.setpoint(joint)
    scene.advance(0.5)
    assert scene.position(joint) == pytest.approx(held, abs=1e-3)
    with pytest.raises(KeyError):
        scene.command_velocity("no_such_joint", 1.0)
    with pytest.raises(ValueError):
        scene.command_position(joint, float("nan"))


def test_width_limit_switch_reads_the_width_joint(scene):
    arm = "ars_x"
    assert scene.limit_switch(arm)
    scene.command_position(names.width_joint(arm), 0.1)
    scene.advance(1.5)
    assert not scene.limit_switch(arm)
    scene.command_position(names.width_joint(arm), 0.0)
    scene.advance(1.5)
    assert scene.limit_switch(arm)


def test_reset_returns_to_the_start(scene):
    scene.command_position(names.arm_joint("ars_x", 0), 1.0)
    scene.advance(0.5)
    scene.reset()
    assert scene.time == 0.0
    assert scene.position(names.arm_joint("ars_x", 0)) == pytest.approx(scene.edu["arms"]["ars_x"]["home"][0])
    assert scene.data.ncon == 0  # nothing touches at the start
    assert scene.truth.active_constraints() == [f"top/{i}/payload" for i in range(4)]
