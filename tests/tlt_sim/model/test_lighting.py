"""The light the twin's cameras see by: the lunar preset's low, hard sun against the model's own."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from tlt_sim.model import names
from tlt_sim.model.cameras import CameraRenderer
from tlt_sim.model.lighting import DEFAULT_LIGHTING, apply_lighting, load_lighting
from tlt_sim.model.scene import Scene

from tlt_common.config_schema import ConfigError


def _luminance(scene: Scene) -> np.ndarray:
    frame = scene.render(names.zed_camera(0), 320, 240, depth=False, segmentation=False, antialias=False)
    return frame.rgb.astype(float) @ [0.299, 0.587, 0.114]


def test_the_model_lights_the_twin_unless_told_otherwise():
    assert load_lighting() is None  # the shipped file keeps the model's own lights
    lunar = load_lighting(name="lunar")
    assert lunar is not None and lunar.shadows
    elevation = math.degrees(math.asin(-lunar.direction()[2]))
    assert elevation == pytest.approx(lunar.elevation_deg) and elevation < 10.0


def test_a_low_hard_sun_darkens_the_scene_and_casts_shadows(tmp_path):
    with Scene(out_dir=tmp_path / "lab") as lab, Scene(out_dir=tmp_path / "moon") as moon:
        apply_lighting(moon.model, load_lighting(name="lunar"))
        mujoco.mj_forward(moon.model, moon.data)
        bright, hard = _luminance(lab), _luminance(moon)
        assert moon.renderer(320, 240, False)._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW]
        assert not lab.renderer(320, 240, False)._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW]
    # Almost no sky light: much of the view goes near black where the lab's stays lit.
    assert (hard < 20).mean() > (bright < 20).mean() + 0.2
    assert hard.mean() < 0.8 * bright.mean()


def test_an_unknown_preset_names_the_file_the_key_and_the_presets(tmp_path):
    with pytest.raises(ConfigError) as err:
        load_lighting(name="noon")
    assert "lighting.yaml: lighting" in str(err.value) and "lunar" in str(err.value)
    bad = tmp_path / "lighting.yaml"
    bad.write_text(DEFAULT_LIGHTING.read_text().replace("elevation_deg: 6.0", "elevation_deg: 120.0"))
    with pytest.raises(ConfigError, match=r"presets\.lunar\.elevation_deg"):
        load_lighting(bad)


def test_renderers_draw_shadows_only_where_a_light_casts_them(tmp_path):
    with Scene(out_dir=tmp_path / "s") as scene:
        plain = CameraRenderer(scene.model, 64, 48, antialias=False)
        apply_lighting(scene.model, load_lighting(name="low_side"))
        shadowed = CameraRenderer(scene.model, 64, 48, antialias=False)
        try:
            assert not plain._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW]
            assert shadowed._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW]
        finally:
            plain.close()
            shadowed.close()
