"""Cameras: frames carry the expected objects, depth and intrinsics agree with ground truth."""

import cv2
import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.cameras import intrinsics
from tlt_sim.model.scene import Scene


@pytest.fixture(scope="module")
def shared(tmp_path_factory):
    """One scene (and GL context) for this module's tests; each test starts from a reset."""
    with Scene(out_dir=tmp_path_factory.mktemp("cameras")) as s:
        yield s


@pytest.fixture
def scene(shared):
    shared.reset()
    return shared


def test_d405_sees_a_strut_tube_and_both_end_fittings(scene):
    camera, part = names.d405_camera("ars_x", "a"), "vertical_dispenser_x/0"
    body = scene.part(part).body
    scene.place_in_view(part, camera, 0.45)
    frame = scene.render(camera, 160, 120)
    seen = frame.instances()
    for piece, cls in (("tube", "strut_tube"), ("fitting_a", "end_fitting"), ("fitting_b", "end_fitting")):
        assert seen.get(f"{body}/{piece}", 0) > 5, (piece, sorted(seen))
        assert frame.class_of(f"{body}/{piece}") == cls
    assert frame.rgb.shape == (120, 160, 3) and frame.depth.shape == (120, 160)
    # Depth on the tube is the distance to it along the optical axis.
    tube = frame.mask(f"{body}/tube")
    assert float(np.median(frame.depth[tube])) == pytest.approx(0.45, abs=0.02)


def test_projected_corners_land_on_their_geoms_in_the_segmentation(scene):
    frame_body = scene.part(scene.stage_bay(1)["bay1/cross_frame"]).body
    camera = names.zed_camera(0)
    scene.command_position(names.camera_mount(0), scene.edu["camera_mounts"]["inward_angle"])
    scene.advance(1.5)
    frame = scene.render(camera, 320, 240)
    k, hits = frame.intrinsics, 0
    for body in ("payload", frame_body):
        for corner in range(4):
            name = f"{body}/corner_{corner}"
            mask = frame.mask(name)
            if mask.sum() < 10 or mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
                continue  # out of view, hidden or cut by the image edge
            target = scene.site_position(names.corner_site(body, corner))
            p = frame.rotation.T @ (target - frame.position)
            projected = np.array([k.fx * p[0] / p[2] + k.cx, k.fy * p[1] / p[2] + k.cy])
            rows, cols = np.nonzero(mask)
            assert np.linalg.norm(projected - [cols.mean(), rows.mean()]) < 4.0, name
            assert float(np.median(frame.depth[mask])) == pytest.approx(p[2], abs=0.04)
            hits += 1
    assert hits >= 3


def test_intrinsics_follow_the_vertical_field_of_view():
    k = intrinsics(90.0, 640, 480)
    assert k.fy == pytest.approx(240.0)
    assert k.fx == k.fy and k.cx == pytest.approx(319.5) and k.cy == pytest.approx(239.5)


def test_zed_mount_turns_inward_to_see_the_bay(scene):
    camera, mount = names.zed_camera(1), names.camera_mount(1)
    tower = ("payload/", scene.part(scene.stage_bay(1)["bay1/cross_frame"]).body + "/")

    def tower_corners() -> set[str]:
        seen = scene.render(camera, 160, 90).instances()
        return {n for n in seen if n.startswith(tower) and "/corner_" in n and seen[n] >= 3}

    outward = tower_corners()
    scene.command_position(mount, scene.edu["camera_mounts"]["inward_angle"])
    scene.advance(1.5)
    inward = tower_corners()
    assert len(inward) >= 4
    assert len(outward) < len(inward)


def test_dispenser_apriltag_is_detected_with_its_id(scene):
    import mujoco

    name = "vertical_dispenser_x"
    cam = mujoco.MjvCamera()
    cam.lookat[:] = scene.site_position(f"dispenser/{name}/tag")
    cam.distance, cam.elevation, cam.azimuth = 0.5, -89.0, 0.0
    gray = cv2.cvtColor(scene.render(cam, 320, 240, depth=False, segmentation=False).rgb, cv2.COLOR_RGB2GRAY)
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11))
    _, ids, _ = detector.detectMarkers(gray)
    assert ids is not None and scene.info.dispenser_tags[name] in ids.ravel().tolist()


def test_renderer_is_made_only_when_a_frame_is_asked_for(tmp_path):
    with Scene(out_dir=tmp_path / "model") as scene:
        scene.advance(0.1)
        assert not scene.cameras._renderers
        scene.render(names.d405_camera("ars_y", "b"), 64, 48, depth=False, segmentation=False)
        assert list(scene.cameras._renderers) == [True]
        with pytest.raises(ValueError, match="exceeds"):
            scene.render(names.zed_camera(0), 5000, 10)


def test_a_loaded_rivet_is_seen_in_the_gun_and_gone_once_fired(scene, mover):
    """The ARS checks a loaded gun with its D405 (vision's rivet inspection): the rivet is drawn at
    the muzzle from loading to firing, and nowhere else."""
    from tlt_sim.model import names

    rivet = names.loaded_rivet_geom("ars_x", "a")
    scene.advance(0.01)
    assert rivet not in scene.render("ars_x/d405_a", 320, 240).instances()
    mover(scene, "ars_x").load_rivet("a", "rivet_dispenser_x")
    scene.advance(0.01)
    seen = scene.render("ars_x/d405_a", 320, 240)
    assert seen.instances().get(rivet, 0) > 100 and seen.class_of(rivet) == "rivet"
    assert scene.fire_rivet("ars_x", "a").loaded
    assert rivet not in scene.render("ars_x/d405_a", 320, 240).instances()


def test_frames_without_antialiasing_come_from_a_renderer_without_multisampling(tmp_path):
    """By default frames are multisampled as the model says (what the vision's detectors learned
    on); ``antialias=False`` renders without (cheaper on the CPU, exact segmentation edges) and
    leaves the model's setting as it was."""
    with Scene(out_dir=tmp_path / "model") as scene:
        samples = scene.model.vis.quality.offsamples
        assert samples > 0
        camera = names.d405_camera("ars_x", "a")
        smooth = scene.render(camera, 64, 48)
        assert scene.renderer()._ctx.offSamples == samples
        sharp = scene.render(camera, 64, 48, antialias=False)
        assert scene.renderer(antialias=False)._ctx.offSamples == 0
        assert scene.model.vis.quality.offsamples == samples, "the model's setting is left as it was"
        assert sharp.rgb.shape == smooth.rgb.shape == (48, 64, 3)
        # Every segmented pixel names an instance the labels know.
        for frame in (smooth, sharp):
            ids = np.unique(frame.segmentation)
            assert ids.min() >= -1 and ids.max() < len(frame.labels.instance_names)


def test_only_the_images_asked_for_are_made(scene):
    camera = names.d405_camera("ars_x", "b")
    full = scene.render(camera, 64, 48)
    seg_only = scene.render(camera, 64, 48, depth=False, segmentation=True, rgb=False)
    assert seg_only.rgb is None and seg_only.depth is None
    assert np.array_equal(seg_only.segmentation, full.segmentation)
    depth_only = scene.render(camera, 64, 48, depth=True, segmentation=False, rgb=False)
    assert depth_only.rgb is None and depth_only.segmentation is None
    assert np.array_equal(depth_only.depth, full.depth)
    assert (full.depth > 0).any() and (full.segmentation >= 0).any()


def test_depth_is_the_distance_at_each_pixel_centre(scene):
    """A depth camera measures along each pixel's centre ray: the floor a lifter ZED sees lies at
    the depth the ray through the pixel centre meets it, in a multisampled frame too (whose depth
    buffer resolved to one sample a third of a pixel off the centre: millimetres on a floor seen
    obliquely, a bias in every pose fitted to the cloud)."""
    scene.advance(0.01)
    frame = scene.render(names.zed_camera(0), 320, 240)
    k = frame.intrinsics
    v, u = np.mgrid[0 : k.height, 0 : k.width]
    rays = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones(u.shape)], -1) @ frame.rotation.T
    with np.errstate(divide="ignore"):
        floor = -frame.position[2] / rays[..., 2]  # the optical depth where each ray meets z = 0
    on_floor = (frame.depth > 0) & (floor > 0) & (np.abs(frame.depth - floor) < 0.01)
    assert on_floor.sum() > 1000
    assert np.median(np.abs(frame.depth - floor)[on_floor]) < 2e-4
