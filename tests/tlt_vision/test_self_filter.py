"""The end effectors' self-filter: boxes and jaws placed in a camera, pixels inside them given no
depth, and the configured bodies against the twin's end effector."""

from pathlib import Path

import numpy as np
import pytest

from tlt_common.geometry.transforms import pose_matrix
from tlt_vision.detections import Detection
from tlt_vision.node_config import load_config
from tlt_vision.pointcloud import Intrinsics, back_project
from tlt_vision.self_filter import (
    EeBox,
    EeJaw,
    EeSelfFilter,
    PlacedBox,
    PlacedCapsule,
    drop_inside,
    off_own_ee,
    own_pixels,
)

K = Intrinsics(fx=100.0, fy=100.0, cx=50.0, cy=50.0)  # a 100 x 100 image
NO_JAWS = {"a": 0.0, "b": 0.0}


def _boxes(*boxes: EeBox) -> EeSelfFilter:
    return EeSelfFilter(boxes, (), 0.0)


def test_pixels_whose_point_lies_inside_a_box_lose_their_depth_and_no_others():
    depth = np.full((100, 100), 1.0, dtype=np.float32)
    depth[0, 0] = 0.0  # no return stays none
    # A box 0.2 m square about the optical axis, 1 m ahead: it holds the points of pixels 40..60.
    box = EeBox("gun", np.zeros(3), np.array([0.1, 0.1, 0.05]), False)
    placed = _boxes(box).place(pose_matrix([0.0, 0.0, 0.0]), pose_matrix([0.0, 0.0, 1.0]), 0.0, NO_JAWS)
    out, dropped = drop_inside(depth, K, placed, margin=0.0)
    assert dropped == 21 * 21
    assert (out[40:61, 40:61] == 0).all()
    assert out[39, 50] == 1.0 and out[61, 50] == 1.0 and out[50, 39] == 1.0
    assert depth[50, 50] == 1.0  # the input is left alone
    # Grown by the margin it takes a pixel more each way; a box behind the surface takes nothing.
    assert drop_inside(depth, K, placed, margin=0.01)[1] == 23 * 23
    behind = _boxes(box).place(pose_matrix([0.0, 0.0, 0.0]), pose_matrix([0.0, 0.0, 1.2]), 0.0, NO_JAWS)
    assert drop_inside(depth, K, behind, margin=0.0)[1] == 0


def _every_pixel_tested(depth: np.ndarray, placed: list, margin: float) -> np.ndarray:
    """What ``drop_inside`` must drop, by its definition: every pixel's point against every shape."""
    v, u = np.nonzero(np.isfinite(depth) & (depth > 0))
    points = back_project(u, v, depth[v, u].astype(float), K)
    inside = np.zeros(len(points), dtype=bool)
    for shape in placed:
        inside |= shape.holds(points, margin)
    want = np.zeros(depth.shape, dtype=bool)
    want[v[inside], u[inside]] = True
    return want


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def test_only_the_pixels_near_a_shape_are_tested_and_none_it_holds_is_missed():
    # Boxes and capsules at random poses, some reaching through the camera's plane or behind it,
    # some beside the image, over a depth image with holes whose pixels also see points inside
    # them, their corners and ends first (where a window too small would cut).
    rng = np.random.default_rng(7)
    for _ in range(30):
        depth = rng.uniform(0.05, 2.0, (100, 100)).astype(np.float32)
        placed: list = []
        seen: list[np.ndarray] = []
        for _ in range(4):
            rot, centre = _random_rotation(rng), rng.uniform([-0.8, -0.8, -0.2], [0.8, 0.8, 1.8])
            half = rng.uniform(0.02, 0.3, 3)
            corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)]) * 0.99
            inner = np.vstack([corners, rng.uniform(-1, 1, (60, 3))])
            placed.append(PlacedBox(rot, centre, half))
            seen.append(centre + (inner * half) @ rot.T)
            end, radius = centre + rng.normal(scale=0.2, size=3), rng.uniform(0.005, 0.1)
            placed.append(PlacedCapsule(centre, end, radius))
            ball = rng.normal(size=(60, 3))
            ball *= radius * 0.99 * rng.uniform(0, 1, (60, 1)) / np.linalg.norm(ball, axis=1, keepdims=True)
            seen.append(np.vstack([centre + ball[:30], end + ball[30:]]))
        points = np.vstack(seen)
        points = points[points[:, 2] > 0.01]
        u = np.rint(points[:, 0] / points[:, 2] * K.fx + K.cx).astype(int)
        v = np.rint(points[:, 1] / points[:, 2] * K.fy + K.cy).astype(int)
        on = (u >= 0) & (u < 100) & (v >= 0) & (v < 100)
        depth[v[on], u[on]] = points[on, 2]
        depth[rng.random((100, 100)) < 0.03] = 0.0
        depth[rng.random((100, 100)) < 0.01] = np.nan
        out, dropped = drop_inside(depth, K, placed, margin=0.01)
        want = _every_pixel_tested(depth, placed, 0.01)
        assert dropped == int(want.sum())
        assert (out[want] == 0).all()
        np.testing.assert_array_equal(out[~want], depth[~want])


def test_a_box_on_the_width_slide_moves_with_the_width_along_flange_x():
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # flange x along camera y
    flange = pose_matrix([0.0, 0.0, 1.0], turn)
    fixed = EeBox("a", np.array([0.1, 0.0, 0.0]), np.ones(3) * 0.01, False)
    sliding = EeBox("b", np.array([0.1, 0.0, 0.0]), np.ones(3) * 0.01, True)
    (rot, at_fixed, _), (_, at_sliding, _) = _boxes(fixed, sliding).place(np.eye(4), flange, 0.2, NO_JAWS)
    np.testing.assert_allclose(rot, turn)
    np.testing.assert_allclose(at_fixed, [0.0, 0.1, 1.0], atol=1e-12)
    np.testing.assert_allclose(at_sliding, [0.0, 0.3, 1.0], atol=1e-12)


def test_a_capsule_takes_the_points_within_its_radius_of_its_segment():
    depth = np.full((100, 100), 1.0, dtype=np.float32)
    # A segment along camera x from -0.1 to 0.1 m, 1 m ahead, radius 0.05: pixels 40..60 across
    # its middle, 35..65 along it up to its round ends.
    capsule = PlacedCapsule(np.array([-0.1, 0.0, 1.0]), np.array([0.1, 0.0, 1.0]), 0.05)
    out, dropped = drop_inside(depth, K, [capsule], margin=0.0)
    assert (out[45:56, 40:61] == 0).all() and (out[50, 35:66] == 0).all()
    assert out[44, 40] == 1.0 and out[50, 34] == 1.0 and out[50, 66] == 1.0
    assert out[46, 36] == 1.0  # past the end, outside the round cap
    assert drop_inside(depth, K, [capsule], margin=0.01)[1] > dropped


def test_a_jaw_turns_about_flange_x_by_its_grasp_joint_and_rides_the_slide():
    jaw = EeJaw("b", np.array([0.25, -0.045, 0.115]), np.array([0.25, 0.0, 0.17]), 0.007, True)
    flt = EeSelfFilter((), (jaw,), 0.0)
    ((start, end, radius),) = flt.place(np.eye(4), np.eye(4), 0.1, {"a": 1.0, "b": np.pi / 2})
    np.testing.assert_allclose(start, [0.35, -0.045, 0.115], atol=1e-12)
    # (0, 0.045, 0.055) from the hinge turned a quarter about x: (0, -0.055, 0.045).
    np.testing.assert_allclose(end, [0.35, -0.1, 0.16], atol=1e-12)
    assert radius == 0.007


scene_mod = pytest.importorskip("tlt_sim.model.scene")
names = pytest.importorskip("tlt_sim.model.names")
ROOT = Path(__file__).resolve().parents[2]


def test_the_configured_bodies_are_the_twins_end_effector_at_any_width_and_grasp(tmp_path):
    config = load_config(ROOT / "config" / "vision" / "node.yaml")
    flt = EeSelfFilter.from_config(config.raw["ee_self_filter"])
    bodies = {b.name.split("/")[0] for b in flt.boxes}
    assert bodies >= {"rivet_gun_a", "rivet_gun_b", "gripper_a", "gripper_b"}
    assert {j.side for j in flt.jaws} == {"a", "b"}
    with scene_mod.Scene(out_dir=tmp_path) as scene:
        m, d = scene.model, scene.data
        for arm, width, grasp in (("ars_x", 0.0, 1.0), ("ars_y", 0.12, -0.2)):
            scene.set_joint_state(names.width_joint(arm), width)
            for side in ("a", "b"):
                scene.set_joint_state(names.grasp_joint(arm, side), grasp + (0.3 if side == "b" else 0.0))
            scene.step()
            position, rotation = scene.body_pose(names.ee_body(arm))
            flange = pose_matrix(position, rotation)
            assert scene.position(names.width_joint(arm)) == pytest.approx(width, abs=1e-3)
            jaws = {side: scene.position(names.grasp_joint(arm, side)) for side in ("a", "b")}
            placed = flt.place(np.eye(4), flange, scene.position(names.width_joint(arm)), jaws)
            for box, (rot, centre, half) in zip(flt.boxes, placed[: len(flt.boxes)], strict=True):
                g = m.geom(f"{arm}/{box.name}").id
                assert m.geom_type[g] == 6, box.name  # mjGEOM_BOX
                np.testing.assert_allclose(centre, d.geom_xpos[g], atol=2e-3, err_msg=box.name)
                np.testing.assert_allclose(rot, d.geom_xmat[g].reshape(3, 3), atol=1e-3, err_msg=box.name)
                np.testing.assert_allclose(half, m.geom_size[g], atol=1e-9, err_msg=box.name)
            for jaw, (start, end, radius) in zip(flt.jaws, placed[len(flt.boxes) :], strict=True):
                g = m.body_geomadr[m.body(f"{arm}/jaw_{jaw.side}").id]
                assert m.geom_type[g] == 3, jaw.side  # mjGEOM_CAPSULE: centre, axis z, half length
                axis = d.geom_xmat[g].reshape(3, 3)[:, 2] * m.geom_size[g][1]
                near, far = d.geom_xpos[g] - axis, d.geom_xpos[g] + axis
                if np.linalg.norm(far - start) < np.linalg.norm(near - start):
                    near, far = far, near
                np.testing.assert_allclose(start, near, atol=1e-3, err_msg=jaw.side)
                np.testing.assert_allclose(end, far, atol=1e-3, err_msg=jaw.side)
                assert radius == pytest.approx(m.geom_size[g][0], abs=1e-9)


def test_a_detection_almost_wholly_on_the_end_effectors_is_set_aside_and_a_part_beside_them_stays():
    depth = np.full((100, 100), 1.0, dtype=np.float32)
    depth[90:, :] = 0.0  # no return there, before any filter
    filtered = depth.copy()
    filtered[20:60, 20:60] = 0.0  # a gun, taken out
    own = own_pixels(depth, filtered)
    assert own.sum() == 40 * 40 and not own[90:].any()  # a pixel never seen is not the gun's

    def det(rows, cols):
        mask = np.zeros((100, 100), dtype=bool)
        mask[rows, cols] = True
        return Detection("end_fitting", mask, 0.4)

    on_gun = det(slice(21, 60), slice(20, 62))  # 39 x 42: a fringe of 2 columns off the gun
    beside = det(slice(30, 50), slice(50, 80))  # half on the gun: a fitting whose mask took it in
    unseen = det(slice(92, 98), slice(0, 10))  # in the depth's hole: left to fail for "no depth"
    kept = off_own_ee([on_gun, beside, unseen], own, share=0.9)
    assert kept == [beside, unseen]
    assert off_own_ee([on_gun], None, 0.9) == [on_gun]  # no filter applied: nothing is known
    assert own_pixels(None, filtered) is None


def test_the_share_that_makes_a_detection_the_end_effectors_is_validated(tmp_path):
    path = Path(__file__).resolve().parents[2] / "config" / "vision" / "node.yaml"
    assert EeSelfFilter.from_config(load_config(path).raw["ee_self_filter"]).own_share == 0.9
    bad = tmp_path / "node.yaml"
    bad.write_text(path.read_text().replace("own_share: 0.9", "own_share: 0.3"))
    with pytest.raises(Exception, match=r"own_share.*0\.5"):
        load_config(bad)
