"""The cameras' sensor models: what the twin's exact renders become as a ZED 2i or a D405 gives them.

Each effect is checked on the twin's own renders where it can be seen there (noise against its
model at two distances, holes at a part's silhouette and in its occlusion shadow, one seed giving
the same frame twice, the mounts' offsets), and on made-up frames where the geometry must be exact
(a thin bar, a saturated spot, the range)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.camera_sensor import (
    DEFAULT_CAMERAS,
    CameraSensors,
    Imager,
    StereoDepth,
    correlated_normal,
    load_camera_sensors,
    offset_mounts,
)
from tlt_sim.model.scene import Scene

from tlt_common.config_schema import ConfigError


@pytest.fixture(scope="module")
def sensors() -> CameraSensors:
    return load_camera_sensors()


@pytest.fixture(scope="module")
def shared(tmp_path_factory):
    with Scene(out_dir=tmp_path_factory.mktemp("camera_sensor")) as s:
        yield s


@pytest.fixture
def scene(shared):
    shared.reset()
    return shared


def _zed_view_of_a_strut(scene: Scene, distance: float = 0.8):
    """A lifter ZED's exact frame of a strut held across its view, and the strut's pixels (its tube
    and end fittings)."""
    camera = names.zed_camera(0)
    part = next(p for p in scene.info.parts.values() if p.kind == "vertical")
    scene.place_in_view(part.name, camera, distance)
    frame = scene.render(camera, 640, 480, antialias=False)
    pieces = [n for n in frame.instances() if n.startswith(f"{part.body}/")]
    return frame, np.logical_or.reduce([frame.mask(n) for n in pieces])


def test_the_shipped_cameras_are_realistic_and_each_its_own(sensors):
    assert sensors.realistic, "the twin's cameras behave like real ones unless asked otherwise"
    assert sensors.for_camera("zed_1") is sensors.zed
    assert sensors.for_camera("ars_x/d405_b") is sensors.d405
    # The datasheets' accuracy: a ZED 2i under 1 % up to 3 m, a D405 within 2 % at 0.5 m.
    assert sensors.zed.depth.sigma(3.0) < 0.01 * 3.0
    assert sensors.d405.depth.sigma(0.5) < 0.02 * 0.5


def test_depth_noise_on_the_twins_render_grows_as_the_square_of_the_distance(scene, sensors):
    # The floor and the machine seen by a lifter ZED: pixels from under a metre to past two.
    camera = names.zed_camera(0)
    frame = scene.render(camera, 640, 480, antialias=False)
    model = dataclasses.replace(
        sensors.zed.depth, edge_px=0.0, thin_px=0.0, dropout=0.0, occlusion=False, specular_luminance=256.0
    )
    noisy = model.apply(frame.depth, None, frame.intrinsics.fx, np.random.default_rng(1))
    valid = (frame.depth > 0) & (noisy > 0)
    measured = []
    for low, high in ((0.9, 1.1), (1.8, 2.2)):
        band = valid & (frame.depth >= low) & (frame.depth < high)
        assert band.sum() > 2000, f"too few pixels between {low} and {high} m"
        error = (noisy - frame.depth)[band]
        z = float(np.median(frame.depth[band]))
        assert np.std(error) == pytest.approx(model.sigma(z), rel=0.2), f"at {z:.2f} m"
        assert abs(float(np.mean(error))) < 0.3 * model.sigma(z), "no bias beyond second order"
        measured.append(np.std(error))
    # Twice the distance, four times the noise.
    assert measured[1] / measured[0] == pytest.approx(4.0, rel=0.35)


def test_a_parts_silhouette_and_its_occlusion_shadow_have_no_depth(scene, sensors):
    frame, strut = _zed_view_of_a_strut(scene)
    noisy = sensors.zed.depth.apply(frame.depth, frame.rgb, frame.intrinsics.fx, np.random.default_rng(2))
    bf = sensors.zed.depth.baseline_m * frame.intrinsics.fx
    rows = np.flatnonzero(strut.any(axis=1))
    checked = 0
    for row in rows[len(rows) // 4 : 3 * len(rows) // 4]:
        line = np.flatnonzero(strut[row])
        left, right = int(line.min()), int(line.max())
        # The silhouette: the strut's outermost pixels.
        assert noisy[row, left] == 0 and noisy[row, right] == 0
        behind = frame.depth[row, left - 12 : left - 2]
        if not (behind > 1.5).all():
            continue
        # The shadow: background just left of the strut, seen by the left imager and hidden from
        # the right one for the disparity difference, has no depth.
        shadow = int(bf / frame.depth[row, left + 3] - bf / behind.max())
        assert shadow >= 5
        assert (noisy[row, left - shadow + 2 : left] == 0).all(), row
        checked += 1
    assert checked >= 3, "too few rows with the floor behind the strut's end"
    # Away from its edges, the strut keeps its depth.
    inner = (
        strut
        & ~np.roll(~strut, 2, 0)
        & ~np.roll(~strut, -2, 0)
        & ~np.roll(~strut, 2, 1)
        & ~np.roll(~strut, -2, 1)
    )
    assert inner.sum() > 200 and (noisy[inner] > 0).mean() > 0.7


def test_the_same_seed_gives_the_same_frame_and_the_next_frame_another(scene, sensors):
    frame, _ = _zed_view_of_a_strut(scene)
    fx = frame.intrinsics.fx
    first = sensors.zed.apply(frame.rgb, frame.depth, fx, sensors.frame_rng("zed_1", 7))
    again = sensors.zed.apply(frame.rgb, frame.depth, fx, sensors.frame_rng("zed_1", 7))
    after = sensors.zed.apply(frame.rgb, frame.depth, fx, sensors.frame_rng("zed_1", 8))
    other = sensors.zed.apply(frame.rgb, frame.depth, fx, sensors.frame_rng("zed_2", 7))
    assert np.array_equal(first[0], again[0]) and np.array_equal(first[1], again[1])
    for different in (after, other):
        assert not np.array_equal(first[0], different[0]) and not np.array_equal(first[1], different[1])
    assert not np.array_equal(first[0], frame.rgb), "the image is not the exact render"


def test_a_thin_bar_loses_pixels_a_wide_one_keeps_them():
    depth = np.full((120, 200), 2.0)
    depth[:, 40:42] = 1.0  # 2 px: thinner than the matcher's window
    depth[:, 120:160] = 1.0  # 40 px
    model = StereoDepth(0.12, 514.0, 0.0, thin_px=4.0, thin_dropout=0.5, occlusion=False)
    out = model.apply(depth, None, 514.0, np.random.default_rng(3))
    assert (out[:, 40:42] == 0).mean() == pytest.approx(0.5, abs=0.1)
    assert (out[:, 125:155] == 0).mean() == 0
    assert (out[:, 60:100] == 0).mean() == 0


def test_specular_spots_and_out_of_range_pixels_have_no_depth():
    depth = np.full((60, 80), 0.5)
    depth[:, :10] = 0.05  # nearer than the D405's minimum
    rgb = np.full((60, 80, 3), 120, dtype=np.uint8)
    rgb[30:34, 40:44] = 255
    rgb[:, 70:] = 255  # bright, but no highlight: as bright as all about it
    model = StereoDepth(0.018, 649.0, 0.0, min_range_m=0.07, specular_luminance=250.0)
    out = model.apply(depth, rgb, 216.0, np.random.default_rng(4))
    assert (out[30:34, 40:44] == 0).all()
    assert (out[:, :10] == 0).all()
    assert (out[5:25, 20:70] > 0).all()
    assert (out[:, 74:] > 0).all()


def test_image_noise_follows_shot_and_read_noise_and_exposure_varies():
    imager = Imager(shot_noise=0.25, read_noise=1.5)
    grey = np.full((200, 200, 3), 100, dtype=np.uint8)
    out = imager.apply(grey, np.random.default_rng(5)).astype(float)
    assert np.std(out - 100) == pytest.approx(np.sqrt(0.25**2 * 100 + 1.5**2), rel=0.05)
    varying = Imager(exposure=(0.7, 1.4))
    means = [varying.apply(grey, np.random.default_rng(i)).mean() for i in range(20)]
    assert 70 <= min(means) < 90 and 120 < max(means) <= 140


def test_correlated_noise_keeps_unit_variance_and_is_shared_by_neighbours():
    noise = correlated_normal((400, 400), 3.0, np.random.default_rng(6))
    assert np.std(noise) == pytest.approx(1.0, rel=0.1)
    neighbours = np.corrcoef(noise[:, :-1].ravel(), noise[:, 1:].ravel())[0, 1]
    assert neighbours > 0.9


def test_each_camera_stands_off_its_mount_by_its_drawn_offset(scene, sensors):
    before = {c: scene.camera_pose(c) for c in names.cameras()}
    nominal = scene.model.cam_pos.copy(), scene.model.cam_quat.copy()
    offset_mounts(scene.model, sensors, names.cameras())
    mujoco.mj_forward(scene.model, scene.data)
    try:
        for camera in names.cameras():
            pos, rot = scene.camera_pose(camera)
            t, r = sensors.mount_offset(camera)
            mount = sensors.for_camera(camera).mount
            p0, r0 = before[camera]
            assert pos == pytest.approx(p0 + r0 @ t, abs=1e-9), camera
            assert rot == pytest.approx(r0 @ r.as_matrix(), abs=1e-9), camera
            assert 0 < np.linalg.norm(t) < 5 * mount.translation_sigma_m
            assert 0 < np.degrees(r.magnitude()) < 5 * mount.rotation_sigma_deg
    finally:
        scene.model.cam_pos[:], scene.model.cam_quat[:] = nominal
        mujoco.mj_forward(scene.model, scene.data)


def test_a_bad_camera_file_names_the_file_the_key_and_the_reason(tmp_path):
    text = DEFAULT_CAMERAS.read_text().replace("baseline_m: 0.12", "baseline_m: -1")
    bad = tmp_path / "cameras.yaml"
    bad.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_camera_sensors(bad)
    message = str(err.value)
    assert "cameras.yaml" in message and "zed.depth.baseline_m" in message
