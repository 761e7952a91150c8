"""The light the twin's cameras see by: the model's own, or the lunar surface's hard, low sun.

The model (``tlt_sim.model.generate``) lights the EDU as a laboratory does: a sun overhead and the viewer's
headlight, soft and even. On the Moon the sun stands a few degrees over the horizon for days at
the poles, with next to no sky light: one face of a part glares, the other is black, and long
shadows cross the site. :func:`apply_lighting` puts a :class:`Lighting` (``config/twin/lighting.yaml``
names them) on a compiled model before its renderers are made; a light that casts shadows makes
the camera renderers draw them (:class:`tlt_sim.model.cameras.CameraRenderer`), at a cost in CPU.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from tlt_common.config_schema import ConfigError, Field, load_validated, opt

REPO = Path(__file__).resolve().parents[3]
DEFAULT_LIGHTING = REPO / "config" / "twin" / "lighting.yaml"
SUN = "sun"  # the model's directional light


@dataclass(frozen=True)
class Lighting:
    """The sun (elevation and azimuth in degrees, world frame; its diffuse intensity), the ambient
    light of the scene, the headlight's, and whether the sun casts shadows. ``None``: the model's
    own lights, untouched."""

    elevation_deg: float
    azimuth_deg: float
    diffuse: float
    ambient: float
    headlight: float
    shadows: bool

    def direction(self) -> np.ndarray:
        """Unit vector the sunlight travels along (from the sun down to the site)."""
        el, az = math.radians(self.elevation_deg), math.radians(self.azimuth_deg)
        towards_sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        return -towards_sun


def apply_lighting(model: mujoco.MjModel, lighting: Lighting | None) -> None:
    """Light ``model`` by ``lighting`` (None: leave the model's own lights)."""
    if lighting is None:
        return
    sun = model.light(SUN).id
    model.light_dir[sun] = lighting.direction()
    model.light_diffuse[sun] = lighting.diffuse
    model.light_specular[sun] = lighting.diffuse
    model.light_ambient[sun] = lighting.ambient
    model.light_castshadow[sun] = lighting.shadows
    model.vis.headlight.ambient[:] = 0.0
    model.vis.headlight.diffuse[:] = lighting.headlight
    model.vis.headlight.specular[:] = 0.0


_PRESET = {
    "elevation_deg": Field("float", minimum=-10.0, maximum=90.0, doc="sun over the horizon"),
    "azimuth_deg": Field("float", minimum=-360.0, maximum=360.0, doc="sun's bearing from world x"),
    "diffuse": Field("float", minimum=0.0, maximum=2.0),
    "ambient": Field("float", minimum=0.0, maximum=1.0),
    "headlight": opt("float", 0.0, minimum=0.0, maximum=1.0),
    "shadows": opt("bool", True),
}
SCHEMA = {
    "format": Field("int", choices=(1,)),
    "lighting": Field("str", doc="a preset's name, or `model` for the model's own lights"),
    "presets": Field("map", item=Field("dict", schema=_PRESET)),
}


def load_lighting(path: str | Path = DEFAULT_LIGHTING, name: str | None = None) -> Lighting | None:
    """The preset ``name`` of ``lighting.yaml`` (by default the file's ``lighting``); None for
    ``model``. A bad file, or a name it does not have, raises ``ConfigError``."""
    doc = load_validated(path, SCHEMA)
    name = name or doc["lighting"]
    if name == "model":
        return None
    if name not in doc["presets"]:
        known = ", ".join(["model", *doc["presets"]])
        raise ConfigError(path, "lighting", f"no preset {name!r} (known: {known})")
    return Lighting(**doc["presets"][name])


__all__ = ["DEFAULT_LIGHTING", "Lighting", "apply_lighting", "load_lighting"]
