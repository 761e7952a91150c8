"""The end effectors' self-filter: boxes placed in a camera, pixels inside them given no depth, and
the configured boxes against the twin's end effector."""

from pathlib import Path

import numpy as np
import pytest

from tlt_ars.planning.kinematics import pose_matrix
from tlt_vision.node_config import load_config
from tlt_vision.pointcloud import Intrinsics
from tlt_vision.self_filter import EeBox, boxes_in_camera, drop_inside, load_boxes

K = Intrinsics(fx=100.0, fy=100.0, cx=50.0, cy=50.0)  # a 100 x 100 image


def test_pixels_whose_point_lies_inside_a_box_lose_their_depth_and_no_others():
    depth = np.full((100, 100), 1.0, dtype=np.float32)
    depth[0, 0] = 0.0  # no return stays none
    # A box 0.2 m square about the optical axis, 1 m ahead: it holds the points of pixels 40..60.
    box = EeBox("gun", np.zeros(3), np.array([0.1, 0.1, 0.05]), False)
    placed = boxes_in_camera([box], pose_matrix([0.0, 0.0, 0.0]), pose_matrix([0.0, 0.0, 1.0]), 0.0)
    out, dropped = drop_inside(depth, K, placed, margin=0.0)
    assert dropped == 21 * 21
    assert (out[40:61, 40:61] == 0).all()
    assert out[39, 50] == 1.0 and out[61, 50] == 1.0 and out[50, 39] == 1.0
    assert depth[50, 50] == 1.0  # the input is left alone
    # Grown by the margin it takes a pixel more each way; a box behind the surface takes nothing.
    assert drop_inside(depth, K, placed, margin=0.01)[1] == 23 * 23
    behind = boxes_in_camera([box], pose_matrix([0.0, 0.0, 0.0]), pose_matrix([0.0, 0.0, 1.2]), 0.0)
    assert drop_inside(depth, K, behind, margin=0.0)[1] == 0


def test_a_box_on_the_width_slide_moves_with_the_width_along_flange_x():
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # flange x along camera y
    flange = pose_matrix([0.0, 0.0, 1.0], turn)
    fixed = EeBox("a", np.array([0.1, 0.0, 0.0]), np.ones(3) * 0.01, False)
    sliding = EeBox("b", np.array([0.1, 0.0, 0.0]), np.ones(3) * 0.01, True)
    (rot, at_fixed, _), (_, at_sliding, _) = boxes_in_camera([fixed, sliding], np.eye(4), flange, 0.2)
    np.testing.assert_allclose(rot, turn)
    np.testing.assert_allclose(at_fixed, [0.0, 0.1, 1.0], atol=1e-12)
    np.testing.assert_allclose(at_sliding, [0.0, 0.3, 1.0], atol=1e-12)


scene_mod = pytest.importorskip("tlt_sim.model.scene")
names = pytest.importorskip("tlt_sim.model.names")
ROOT = Path(__file__).resolve().parents[2]


def test_the_configured_boxes_are_the_twins_end_effector_at_any_width(tmp_path):
    config = load_config(ROOT / "config" / "vision" / "node.yaml")
    boxes = load_boxes(config.raw["ee_self_filter"]["boxes"])
    assert {b.name.split("/")[0] for b in boxes} >= {"rivet_gun_a", "rivet_gun_b", "gripper_a", "gripper_b"}
    with scene_mod.Scene(out_dir=tmp_path) as scene:
        m, d = scene.model, scene.data
        for arm, width in (("ars_x", 0.0), ("ars_y", 0.12)):
            scene.set_joint_state(names.width_joint(arm), width)
            scene.step()
            position, rotation = scene.body_pose(names.ee_body(arm))
            flange = pose_matrix(position, rotation)
            assert scene.position(names.width_joint(arm)) == pytest.approx(width, abs=1e-3)
            placed = boxes_in_camera(boxes, np.eye(4), flange, scene.position(names.width_joint(arm)))
            for box, (rot, centre, half) in zip(boxes, placed, strict=True):
                g = m.geom(f"{arm}/{box.name}").id
                assert m.geom_type[g] == 6, box.name  # mjGEOM_BOX
                np.testing.assert_allclose(centre, d.geom_xpos[g], atol=2e-3, err_msg=box.name)
                np.testing.assert_allclose(rot, d.geom_xmat[g].reshape(3, 3), atol=1e-3, err_msg=box.name)
                np.testing.assert_allclose(half, m.geom_size[g], atol=1e-9, err_msg=box.name)
