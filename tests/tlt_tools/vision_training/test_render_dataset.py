"""The training-image renderer against the twin: the set reads back, masks, depth, classes and poses
agree with each other and with the CAD models, seeds reproduce, defects are recorded, bad options
exit 2. Tiny images (160x120) keep it to seconds."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from tlt_tools.vision_training.dataset import ImageSet

from tlt_vision.cad.models import models_for_mission
from tlt_vision.segmentation.config import CLASSES

pytest.importorskip("tlt_sim.model.scene")
from tlt_sim.model import names
from tlt_tools.vision_training.render_dataset import PREVIEW, main
from tlt_tools.vision_training.twin_renderer import ARMS, ZED, RenderSettings, TwinRenderer

W, H = 160, 120


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("set")
    rc = main(["--out", str(out), "--count", "3", "--seed", "1", "--width", str(W), "--height", str(H)])
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def renderer():
    r = TwinRenderer(RenderSettings(width=W, height=H, seed=1))
    yield r
    r.close()


def _interior(mask: np.ndarray) -> np.ndarray:
    """The mask less its 1-px border: border pixels mix the part's depth with the background's."""
    m = mask.copy()
    m[1:] &= mask[:-1]
    m[:-1] &= mask[1:]
    m[:, 1:] &= mask[:, :-1]
    m[:, :-1] &= mask[:, 1:]
    return m


def _points(mask: np.ndarray, depth: np.ndarray, k: np.ndarray) -> np.ndarray:
    v, u = np.nonzero(mask)
    z = depth[v, u].astype(float)
    return np.column_stack([(u - k[0, 2]) * z / k[0, 0], (v - k[1, 2]) * z / k[1, 1], z])


def test_set_reads_back_with_consistent_masks_depth_and_poses(rendered, renderer, capsys):
    images = ImageSet(rendered)
    assert len(images) == 3 and images.classes == list(CLASSES)
    assert images.index["width"] == W and images.index["settings"]["min_pixels"] >= 20
    assert (rendered / PREVIEW).stat().st_size > 1000
    models = models_for_mission(renderer.scene.mission)
    checked = 0
    for i in range(len(images)):
        s = images[i]
        assert s.rgb.shape == (H, W, 3) and s.depth.dtype == np.float32 and len(s.labels) > 0
        assert (s.depth >= 0).all() and (s.depth > 0).any()
        assert (s.labels >= 1).all() and (s.labels <= len(CLASSES)).all()
        rows = zip(s.masks, s.labels, s.names, s.poses, s.defects, strict=True)
        for mask, label, name, pose, defect in rows:
            assert mask.sum() >= images.index["settings"]["min_pixels"], name
            inner = _interior(mask)
            assert (s.depth[inner] > 0).all(), name  # the part was hit wherever it is labelled
            cls = CLASSES[label - 1]
            if inner.sum() < 10 or defect == "bent_tube":  # a bent tube has no straight model to fit
                continue
            # The masked depth, back-projected, lies on the CAD model at the stored pose.
            pts = _points(inner, s.depth, s.intrinsics)
            local = (pts - pose[:3, 3]) @ pose[:3, :3]
            names = [n for n in models if n.startswith("strut_tube/")] if cls == "strut_tube" else [cls]
            d = min(
                float(np.percentile(models[n].surface(torch.tensor(local, dtype=torch.float32)).numpy(), 90))
                for n in names
            )
            assert d < 0.006, (name, d)
            checked += 1
    assert checked >= 5


def test_a_part_placed_in_view_is_found_with_its_class_name_and_pose(renderer):
    scene = renderer.scene
    part = next(p for p in renderer.struts["vertical"] if renderer.parts[p].defect is None)
    body = scene.part(part).body
    scene.reset()
    scene.place_in_view(part, ZED, 0.5)  # across the view, centred 0.5 m ahead
    sample = renderer._capture(ZED)
    names = list(sample.names)
    tube = names.index(f"{body}/tube")
    assert CLASSES[sample.labels[tube] - 1] == "strut_tube" and sample.defects[tube] == ""
    # At 160x120 a fitting is a few dozen pixels; one may fall under min_pixels where it is partly hidden.
    fittings = [i for i, n in enumerate(names) if n.startswith(f"{body}/fitting_")]
    assert fittings and all(CLASSES[sample.labels[i] - 1] == "end_fitting" for i in fittings)
    found = {CLASSES[label - 1] for n, label in zip(names, sample.labels, strict=True) if n.startswith(body)}
    assert found == {"strut_tube", "end_fitting"}
    pose = sample.poses[tube]
    np.testing.assert_allclose(pose[:3, 3], [0.0, 0.0, 0.5], atol=1e-6)
    assert abs(pose[0, 2]) > 1 - 1e-6  # the strut's axis along the image's x
    # Each part's centre projects into its own mask (a fitting's centre is on its visible face).
    for i in (tube, *fittings):
        u, v, w = sample.intrinsics @ sample.poses[i][:3, 3]
        assert sample.masks[i][round(v / w), round(u / w)], names[i]


def test_rivets_in_a_feeder_are_labelled_and_posed(renderer):
    settings = renderer.settings
    # At 160x120 a rivet 0.4 m away covers about 20 pixels, under the default threshold.
    renderer.settings = replace(settings, min_pixels=8)
    try:
        renderer.scene.reset()
        sample = renderer._capture(renderer._feeder(np.random.default_rng(2)))
    finally:
        renderer.settings = settings
    rivets = [i for i, label in enumerate(sample.labels) if CLASSES[label - 1] == "rivet"]
    assert rivets
    for i in rivets:
        assert sample.names[i].startswith("dispenser/rivet_dispenser_")
        u, v, w = sample.intrinsics @ sample.poses[i][:3, 3]
        assert sample.masks[i][round(v / w), round(u / w)], sample.names[i]


def test_a_presented_strut_lies_in_an_arms_grasp_and_is_in_view(renderer):
    scene = renderer.scene
    scene.reset()
    sample = renderer._capture(renderer._presented(np.random.default_rng(4)))
    seated = []
    for arm in ARMS:
        centre, axis = scene.assembly.grasp_line(arm)
        for name in (*renderer.struts["vertical"], *renderer.struts["diagonal"]):
            pos, rot = scene.body_pose(scene.part(name).body)
            a, b = (pos + rot @ scene.part(name).ends[e] for e in ("a", "b"))
            along = (b - a) / np.linalg.norm(b - a)
            off = (centre - a) - ((centre - a) @ along) * along
            if np.linalg.norm(off) < 1e-6 and abs(along @ axis) > 1 - 1e-9:
                seated.append((arm, name))
    assert len(seated) == 1, seated  # one strut, on one arm's grasp line
    arm = seated[0][0]
    for side in ("a", "b"):  # the jaws closed on it, as the ARS presents it
        assert scene.position(names.grasp_joint(arm, side)) == scene.edu["end_effector"]["jaw_contact"]
    body = scene.part(seated[0][1]).body
    assert f"{body}/tube" in list(sample.names)


def test_scene_kinds_are_drawn_by_their_weights(tmp_path):
    out = tmp_path / "set"
    argv = ["--out", str(out), "--count", "3", "--width", str(W), "--height", str(H), "--scenes"]
    assert main([*argv, "presented=1", "held=0"]) == 0
    settings = json.loads((out / "index.json").read_text())["settings"]
    assert settings["scenes"] == {"presented": 1.0, "held": 0.0}
    assert set(settings["scene_kinds"].values()) == {"presented"}


def test_same_seed_same_images_another_seed_others(rendered, renderer):
    first = ImageSet(rendered)[0]
    again, _ = renderer.sample(0)
    np.testing.assert_array_equal(again.rgb, first.rgb)
    np.testing.assert_array_equal(again.masks, first.masks)
    np.testing.assert_array_equal(again.poses, first.poses)
    other = TwinRenderer(RenderSettings(width=W, height=H, seed=2, defective_fraction=1.0))
    try:
        assert not np.array_equal(other.sample(0)[0].rgb, first.rgb)
        # Every strut put in view is defective, and the defect is recorded on its instances.
        struts = 0
        for i in range(1, 3):
            s, _ = other.sample(i)
            for name, label, defect in zip(s.names, s.labels, s.defects, strict=True):
                if CLASSES[label - 1] == "strut_tube":
                    struts += 1
                    part = other.by_body[name.rsplit("/", 1)[0]]
                    assert defect == part.defect.kind and defect in ("missing_end_fitting", "bent_tube")
        assert struts > 0
        assert all(d["kind"] in ("missing_end_fitting", "bent_tube") for d in other.defects.values())
        assert len(other.defects) == sum(len(v) for v in other.struts.values())
    finally:
        other.close()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--count", "0"], "--count"),
        (["--count", "1", "--mission", "missions/nope.yaml"], "nope.yaml"),
        (["--count", "1", "--defective-fraction", "1.5"], "--defective-fraction"),
        (["--count", "1", "--width", "5000"], "offscreen buffer"),
        (["--count", "1", "--scenes", "fog=1"], "unknown scene kind 'fog'"),
        (["--count", "1", "--scenes", "held=lots"], "'held=lots': the weight must be a number"),
        (["--count", "1", "--scenes", "held=-1"], "must not be negative"),
        (["--count", "1", "--scenes", "held=0"], "no scene kind has a weight above 0"),
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, args, message):
    assert main(["--out", str(tmp_path / "set"), *args]) == 2
    assert message in capsys.readouterr().err


def test_unwritable_out_exits_2(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["--out", str(Path(blocker) / "set"), "--count", "1"]) == 2
    assert "cannot write" in capsys.readouterr().err


def test_images_through_the_camera_models_have_the_cameras_holes_and_noise_and_reproduce(tmp_path):
    from tlt_sim.model.camera_sensor import DEFAULT_CAMERAS

    exact = TwinRenderer(RenderSettings(width=W, height=H, seed=5))
    real = TwinRenderer(RenderSettings(width=W, height=H, seed=5, cameras=str(DEFAULT_CAMERAS)))
    try:
        (a, _), (b, _), (again, _) = exact.sample(0), real.sample(0), real.sample(0)
    finally:
        exact.close()
        real.close()
    assert np.array_equal(a.masks, b.masks) and np.array_equal(a.poses, b.poses), "the same scene"
    assert np.array_equal(b.rgb, again.rgb) and np.array_equal(b.depth, again.depth), "one seed, one image"
    seen = a.depth > 0
    assert ((b.depth == 0) & seen).sum() > 0.005 * seen.sum(), "the real camera's holes"
    both = seen & (b.depth > 0)
    assert 0 < np.median(np.abs(b.depth[both] - a.depth[both])) < 0.01, "noise of millimetres"
    assert not np.array_equal(a.rgb, b.rgb)


def test_images_lit_by_the_lunar_sun_are_darker_than_by_the_random_lights():
    lit = TwinRenderer(RenderSettings(width=W, height=H, seed=6))
    moon = TwinRenderer(RenderSettings(width=W, height=H, seed=6, lighting="lunar"))
    try:
        means = [(lit.sample(i)[0].rgb.mean(), moon.sample(i)[0].rgb.mean()) for i in range(3)]
    finally:
        lit.close()
        moon.close()
    assert all(dark < bright for bright, dark in means), means
