"""The vision benchmark's noise (a fraction of each pixel's depth, grey levels on its colours, the
same every run) and its account of the views left uncertified."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tlt_tools.vision_training.dataset import Sample


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("vision")


def _sample(depth: np.ndarray) -> Sample:
    h, w = depth.shape
    return Sample(
        rgb=np.zeros((h, w, 3), np.uint8),
        depth=depth,
        masks=np.zeros((0, h, w), bool),
        labels=np.zeros(0, np.int64),
        names=np.array([], dtype=str),
        poses=np.zeros((0, 4, 4)),
        defects=np.array([], dtype=str),
        intrinsics=np.eye(3),
    )


def test_depth_noise_is_a_fraction_of_each_pixels_depth_and_the_same_every_run(bench):
    depth = np.concatenate([np.full((100, 100), 1.0), np.full((100, 100), 4.0)]).astype(np.float32)
    noisy = bench.with_depth_noise(_sample(depth), 0.01, index=3)
    assert noisy.depth.dtype == np.float32 and noisy.depth.shape == depth.shape
    spread = (noisy.depth - depth) / depth
    assert spread.std() == pytest.approx(0.01, rel=0.05)
    near, far = abs(noisy.depth - depth)[:100].mean(), abs(noisy.depth - depth)[100:].mean()
    assert far == pytest.approx(4 * near, rel=0.1)  # four times as deep, four times the noise
    again = bench.with_depth_noise(_sample(depth), 0.01, index=3)
    assert np.array_equal(noisy.depth, again.depth)
    assert not np.array_equal(noisy.depth, bench.with_depth_noise(_sample(depth), 0.01, index=4).depth)


def test_image_noise_is_grey_levels_on_each_colour_clipped_and_the_same_every_run(bench):
    sample = _sample(np.ones((200, 200), np.float32))
    rgb = np.full((200, 200, 3), 128, np.uint8)
    rgb[:, :10] = 0  # black: the noise below zero is clipped
    sample = dataclasses.replace(sample, rgb=rgb)
    noisy = bench.with_image_noise(sample, 4.0, index=3)
    assert noisy.rgb.dtype == np.uint8 and noisy.rgb.shape == rgb.shape
    assert (noisy.rgb[:, 10:].astype(float) - 128).std() == pytest.approx(4.0, rel=0.05)
    assert noisy.rgb[:, :10].min() == 0 and 0 < noisy.rgb[:, :10].mean() < 4
    assert np.array_equal(noisy.rgb, bench.with_image_noise(sample, 4.0, index=3).rgb)
    assert np.array_equal(noisy.depth, sample.depth)


def test_views_left_uncertified_are_reported_by_the_certificates_reason(bench, capsys):
    kind = bench.refusal_kind
    assert kind("not observably correct: 90% Chamfer distance 9.3 mm > threshold 2.5 mm") == (
        "Chamfer over threshold"
    )
    both = "not observably correct: ...; degenerate view: 1 of 2 required keypoint groups visible"
    assert kind(both) == "Chamfer over threshold"  # the first reason names it
    assert kind("degenerate view: 1 of 2 required keypoint groups visible") == "degenerate at its pose"
    assert kind("posed model where the camera saw past it: 30% of its surface ...") == "seen past"
    assert kind("depth too noisy to certify at 0.84 m: ...") == "depth too noisy"
    assert kind("something new: details") == "something new"

    tally = bench.PoseTally()
    tally.estimated["end_fitting"] = tally.whole["end_fitting"] = tally.reach["end_fitting"] = 3
    tally.shown["end_fitting"] = 4  # one more the detection's mask fell short of
    tally.refused["end_fitting"]["Chamfer over threshold", True] += 1
    tally.refused["end_fitting"]["Chamfer over threshold", False] += 1
    tally.refused["end_fitting"]["seen past", False] += 1
    bench.report_poses("on masks", tally, 0.02)
    out = capsys.readouterr().out
    assert "certified 0/3 = 0.0 %" in out
    assert "of the 4 views in which the twin's mask of the part shows enough of it" in out
    assert "    end_fitting   Chamfer over threshold 2 [1], seen past 1 [0]\n" in out
    assert bench.pose_summary(tally) == {
        "posed": 3,
        "certified": 0,
        "views": 3,
        "views_certified": 0,
        "views_shown": 4,
        "views_shown_certified": 0,
        "add_s_ok": 0,
        "median_rotation_deg": None,
        "median_translation_mm": None,
    }


def test_an_images_camera_is_told_by_its_optics_so_the_pipeline_knows_its_noise(bench):
    import math

    optics = bench.CameraOptics()
    for camera, fovy in (("zed_1", 70.0), ("ars_x/d405_a", 58.0)):
        for height in (120, 480):
            k = np.diag([1.0, height / 2 / math.tan(math.radians(fovy) / 2), 1.0])
            assert optics(k, height) == camera
