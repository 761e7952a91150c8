"""What a real camera makes of the twin's perfect render: the ZED 2i's and D405's sensor effects.

The renderer (:mod:`tlt_sim.model.cameras`) gives exact colours and depth. A real camera does not,
and the vision system must be judged on what a real one gives. :class:`CameraSensor` turns one
exact frame into what the camera would deliver, reproducibly from a random generator:

Depth (:class:`StereoDepth`), both cameras being stereo pairs whose depth map is aligned with the
left imager:

* **noise** from sub-pixel disparity error: disparity ``d = b f / z`` (baseline ``b``, focal length
  ``f`` in pixels) takes Gaussian noise of ``disparity_sigma_px``, so the depth error grows as
  ``z^2 sigma_d / (b f)``. The noise is correlated over ``correlation_px`` (the matcher's window
  makes neighbouring pixels err together), which a median filter removes less well than
  independent noise. ``f`` and the pixel figures are at the sensor's native resolution; the
  effect is the same at any render size.
* **occlusion shadows**: a pixel the left imager sees but the right one does not (just left of a
  nearer object, by the disparity difference) has no depth.
* **edges**: a band of ``edge_px`` native pixels about every depth discontinuity (a jump over
  ``edge_jump`` of the depth) has no depth, where the matcher's window straddles two surfaces.
* **thin parts**: surfaces narrower than ``thin_px`` native pixels in front of what lies behind
  them (found by a morphological closing of the depth) lose each pixel with ``thin_dropout``.
* **specular spots**: where the rendered colour is near saturation (luminance over
  ``specular_luminance``) and stands out from its surroundings (``specular_contrast`` grey levels
  over the mean of the 9 x 9 pixels about it), the highlight differs between the two views and
  the pixel has no depth.
* **range** outside ``[min_range_m, max_range_m]`` and a ``dropout`` share of scattered pixels:
  no depth.

Colour (:class:`Imager`): an exposure gain drawn per frame log-uniformly in ``exposure``, a white
balance error per channel, vignetting towards the corners, then photon (shot) noise growing with
the square root of the signal and read noise, each in grey levels, rounded and clipped to 8 bits.

Mount (:class:`MountError`): each camera stands a little off its nominal mount, a translation and
a rotation drawn once per camera from the configuration's seed (:func:`mount_offsets`); the twin
renders from the true pose, the system knows only the nominal one.

"No depth" is 0, as on the twin's exact frames and the ROS depth images (32FC1).
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from tlt_common.config_schema import Field, load_validated, opt
from tlt_common.pixel_noise import correlated_field

REPO = Path(__file__).resolve().parents[3]
DEFAULT_CAMERAS = REPO / "config" / "twin" / "cameras.yaml"
# Rec. 601 luma weights for the specular test.
_LUMA = np.array([0.299, 0.587, 0.114])
# A MuJoCo camera's axes (x right, y up, z backwards) to the optical frame's (x right, y down,
# z forwards): half a turn about x.
_OPTICAL = Rotation.from_matrix(np.diag([1.0, -1.0, -1.0]))


@dataclass(frozen=True)
class StereoDepth:
    """A stereo depth camera's errors; pixel figures at its native resolution, whose focal length is
    ``focal_px`` (a render of focal length ``fx`` has ``fx / focal_px`` pixels per native pixel)."""

    baseline_m: float
    focal_px: float
    disparity_sigma_px: float
    correlation_px: float = 0.0
    min_range_m: float = 0.0
    max_range_m: float = math.inf
    edge_px: float = 0.0
    edge_jump: float = 0.05
    occlusion: bool = True
    thin_px: float = 0.0
    thin_dropout: float = 0.0
    specular_luminance: float = 256.0
    specular_contrast: float = 30.0
    dropout: float = 0.0

    def sigma(self, z: np.ndarray | float) -> np.ndarray | float:
        """1 sigma of the depth error (m) at depth ``z`` (m), to first order."""
        return np.square(z) * self.disparity_sigma_px / (self.baseline_m * self.focal_px)

    def apply(
        self, depth: np.ndarray, rgb: np.ndarray | None, fx: float, rng: np.random.Generator
    ) -> np.ndarray:
        """``depth`` (metres, 0 = none) rendered with focal length ``fx`` (pixels) as this camera
        measures it; ``rgb`` (the same view's exact colours) locates specular spots."""
        z = np.asarray(depth, dtype=np.float64)
        valid = z > 0
        scale = fx / self.focal_px  # render pixels per native pixel
        bf = self.baseline_m * fx  # disparity (render px) times depth
        disparity = np.where(valid, bf / np.where(valid, z, 1.0), 0.0)
        holes = ~valid
        if self.occlusion:
            holes |= _occluded(disparity) & valid
        if self.edge_px > 0:
            holes |= _edge_band(z, valid, self.edge_jump, self.edge_px * scale)
        if self.thin_px > 0 and self.thin_dropout > 0:
            thin = _thin(z, valid, self.thin_px * scale, self.edge_jump)
            holes |= thin & (rng.random(z.shape) < self.thin_dropout)
        if rgb is not None and self.specular_luminance < 255.0:
            luma = np.asarray(rgb, dtype=np.float64) @ _LUMA
            surround = ndimage.uniform_filter(luma, 9, mode="nearest")
            holes |= (luma >= self.specular_luminance) & (luma - surround > self.specular_contrast)
        if self.dropout > 0:
            holes |= rng.random(z.shape) < self.dropout
        noise = correlated_normal(z.shape, self.correlation_px * scale, rng)
        noisy_disparity = disparity + self.disparity_sigma_px * scale * noise
        out = np.where(noisy_disparity > 0, bf / np.where(noisy_disparity > 0, noisy_disparity, 1.0), 0.0)
        holes |= (z < self.min_range_m) | (z > self.max_range_m) | (noisy_disparity <= 0)
        out[holes] = 0.0
        return out.astype(np.float32)


@dataclass(frozen=True)
class Imager:
    """An 8-bit colour imager's exposure and noise, in grey levels of 255."""

    exposure: tuple[float, float] = (1.0, 1.0)
    white_balance_sigma: float = 0.0
    vignetting: float = 0.0
    shot_noise: float = 0.0
    read_noise: float = 0.0

    def apply(self, rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """``rgb`` (h, w, 3 uint8, exact) as this imager delivers it."""
        img = np.asarray(rgb, dtype=np.float64)
        lo, hi = self.exposure
        gain = math.exp(rng.uniform(math.log(lo), math.log(hi))) if hi > lo else lo
        channel = gain * (1.0 + self.white_balance_sigma * rng.standard_normal(3))
        img = img * np.clip(channel, 0.0, None)
        if self.vignetting > 0:
            h, w = img.shape[:2]
            yy, xx = np.ogrid[:h, :w]
            r2 = ((xx - (w - 1) / 2) / (w / 2)) ** 2 + ((yy - (h - 1) / 2) / (h / 2)) ** 2
            img *= (1.0 - self.vignetting * r2 / 2.0)[..., None]
        if self.shot_noise > 0 or self.read_noise > 0:
            sigma = np.sqrt(self.shot_noise**2 * np.clip(img, 0.0, None) + self.read_noise**2)
            img = img + sigma * rng.standard_normal(img.shape)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class MountError:
    """How far a camera may stand off its nominal mount: 1 sigma per axis."""

    translation_sigma_m: float = 0.0
    rotation_sigma_deg: float = 0.0

    def draw(self, rng: np.random.Generator) -> tuple[np.ndarray, Rotation]:
        """A translation (m) and a rotation, both in the camera's own frame."""
        t = self.translation_sigma_m * rng.standard_normal(3)
        rotvec = np.radians(self.rotation_sigma_deg) * rng.standard_normal(3)
        return t, Rotation.from_rotvec(rotvec)


@dataclass(frozen=True)
class CameraSensor:
    """One camera model: its depth, its imager and its mount error."""

    depth: StereoDepth
    image: Imager
    mount: MountError

    def apply(
        self, rgb: np.ndarray | None, depth: np.ndarray | None, fx: float, rng: np.random.Generator
    ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The exact ``rgb`` and ``depth`` of one frame (either may be None) as the camera gives
        them. The specular test reads the exact colours, before exposure and noise."""
        noisy_depth = None if depth is None else self.depth.apply(depth, rgb, fx, rng)
        noisy_rgb = None if rgb is None else self.image.apply(rgb, rng)
        return noisy_rgb, noisy_depth


@dataclass(frozen=True)
class CameraSensors:
    """The twin's camera models (``config/twin/cameras.yaml``). ``realistic`` False: exact frames."""

    realistic: bool
    seed: int
    zed: CameraSensor
    d405: CameraSensor

    def for_camera(self, camera: str) -> CameraSensor:
        return self.d405 if "d405" in camera else self.zed

    def frame_rng(self, camera: str, index: int) -> np.random.Generator:
        """The generator of ``camera``'s frame number ``index``: the same seed, camera and index
        give the same noise."""
        return np.random.default_rng([self.seed, zlib.crc32(camera.encode()), index])

    def mount_offset(self, camera: str) -> tuple[np.ndarray, Rotation]:
        """``camera``'s fixed offset from its nominal mount, drawn from the seed and its name."""
        rng = np.random.default_rng([self.seed, zlib.crc32(camera.encode()), 0x5EED])
        return self.for_camera(camera).mount.draw(rng)


def offset_mounts(model: mujoco.MjModel, sensors: CameraSensors, cameras: Iterable[str]) -> None:
    """Stand each of ``cameras`` of ``model`` off its nominal mount by its drawn offset (given in
    its optical frame). Call ``mujoco.mj_forward`` afterwards for the data to follow."""
    for camera in cameras:
        cid = model.camera(camera).id
        t, r = sensors.mount_offset(camera)
        mount = Rotation.from_quat(model.cam_quat[cid], scalar_first=True)
        model.cam_pos[cid] = model.cam_pos[cid] + mount.apply(_OPTICAL.apply(t))
        model.cam_quat[cid] = (mount * _OPTICAL * r * _OPTICAL.inv()).as_quat(scalar_first=True)


def correlated_normal(shape: tuple[int, ...], length_px: float, rng: np.random.Generator) -> np.ndarray:
    """Standard normal noise of ``shape`` that neighbouring pixels share over ``length_px``."""
    return correlated_field(rng.standard_normal(shape), length_px)


def _occluded(disparity: np.ndarray) -> np.ndarray:
    """Pixels of the left view hidden from the right one. Pixel ``x`` (disparity ``d_x``) is hidden
    by a nearer pixel ``x + k`` when ``d_{x+k} - d_x >= k``, that is when the largest ``d_j - j``
    to its right reaches ``d_x - x``."""
    w = disparity.shape[1]
    g = disparity - np.arange(w)[None, :]
    right_max = np.maximum.accumulate(g[:, ::-1], axis=1)[:, ::-1]  # max over j >= x
    beyond = np.full_like(g, -np.inf)
    beyond[:, :-1] = right_max[:, 1:]  # max over j > x
    return beyond >= g


def _edge_band(z: np.ndarray, valid: np.ndarray, jump: float, width_px: float) -> np.ndarray:
    """Pixels within ``width_px`` of a depth discontinuity (neighbours differing by over ``jump``
    of the nearer depth, or a valid pixel beside one with no depth)."""
    edge = np.zeros_like(valid)
    for axis in (0, 1):
        a = np.take(z, range(z.shape[axis] - 1), axis=axis)
        b = np.take(z, range(1, z.shape[axis]), axis=axis)
        va = np.take(valid, range(z.shape[axis] - 1), axis=axis)
        vb = np.take(valid, range(1, z.shape[axis]), axis=axis)
        step = (va != vb) | (va & vb & (np.abs(a - b) > jump * np.minimum(a, b)))
        lead = [slice(None)] * 2
        lead[axis] = slice(0, -1)
        trail = [slice(None)] * 2
        trail[axis] = slice(1, None)
        edge[tuple(lead)] |= step
        edge[tuple(trail)] |= step
    radius = math.floor(width_px / 2.0)
    if radius >= 1:
        edge = ndimage.binary_dilation(edge, iterations=radius)
    return edge & valid


def _thin(z: np.ndarray, valid: np.ndarray, width_px: float, jump: float) -> np.ndarray:
    """Valid pixels of surfaces narrower than ``width_px`` standing in front of what is behind
    them: where closing the depth (no depth counted as far) over that width raises it by more than
    ``jump`` of itself."""
    size = round(width_px)
    if size < 2:
        return np.zeros_like(valid)
    far = np.where(valid, z, 1e3)
    closed = ndimage.grey_closing(far, size=(size, size))
    return valid & (closed - far > jump * far)


def _sensor(doc: dict[str, Any]) -> CameraSensor:
    d, i, m = doc["depth"], doc["image"], doc["mount"]
    return CameraSensor(
        depth=StereoDepth(
            baseline_m=d["baseline_m"],
            focal_px=d["focal_px"],
            disparity_sigma_px=d["disparity_sigma_px"],
            correlation_px=d["correlation_px"],
            min_range_m=d["min_range_m"],
            max_range_m=d["max_range_m"],
            edge_px=d["edge_px"],
            edge_jump=d["edge_jump"],
            occlusion=d["occlusion"],
            thin_px=d["thin_px"],
            thin_dropout=d["thin_dropout"],
            specular_luminance=d["specular_luminance"],
            specular_contrast=d["specular_contrast"],
            dropout=d["dropout"],
        ),
        image=Imager(
            exposure=(float(i["exposure"][0]), float(i["exposure"][1])),
            white_balance_sigma=i["white_balance_sigma"],
            vignetting=i["vignetting"],
            shot_noise=i["shot_noise"],
            read_noise=i["read_noise"],
        ),
        mount=MountError(m["translation_sigma_m"], m["rotation_sigma_deg"]),
    )


def _exposure(value: Any) -> str | None:
    if (
        len(value) != 2
        or not all(isinstance(v, int | float) for v in value)
        or not 0 < value[0] <= value[1] <= 8
    ):
        return f"expected [low, high] gains with 0 < low <= high <= 8, got {value!r}"
    return None


_CAMERA = {
    "depth": Field(
        "dict",
        schema={
            "baseline_m": Field("float", minimum=0.001, maximum=1.0, doc="stereo baseline"),
            "focal_px": Field("float", minimum=10.0, maximum=10000.0, doc="focal length, native pixels"),
            "disparity_sigma_px": Field("float", minimum=0.0, maximum=5.0, doc="sub-pixel disparity error"),
            "correlation_px": opt("float", 0.0, minimum=0.0, maximum=20.0),
            "min_range_m": opt("float", 0.0, minimum=0.0, maximum=10.0),
            "max_range_m": opt("float", 100.0, minimum=0.01, maximum=1000.0),
            "edge_px": opt("float", 0.0, minimum=0.0, maximum=20.0),
            "edge_jump": opt("float", 0.05, minimum=0.001, maximum=1.0),
            "occlusion": opt("bool", True),
            "thin_px": opt("float", 0.0, minimum=0.0, maximum=50.0),
            "thin_dropout": opt("float", 0.0, minimum=0.0, maximum=1.0),
            "specular_luminance": opt("float", 256.0, minimum=0.0, maximum=256.0),
            "specular_contrast": opt("float", 30.0, minimum=0.0, maximum=255.0),
            "dropout": opt("float", 0.0, minimum=0.0, maximum=0.5),
        },
    ),
    "image": Field(
        "dict",
        schema={
            "exposure": opt("list", [1.0, 1.0], check=_exposure),
            "white_balance_sigma": opt("float", 0.0, minimum=0.0, maximum=0.5),
            "vignetting": opt("float", 0.0, minimum=0.0, maximum=0.9),
            "shot_noise": opt("float", 0.0, minimum=0.0, maximum=5.0),
            "read_noise": opt("float", 0.0, minimum=0.0, maximum=30.0),
        },
    ),
    "mount": Field(
        "dict",
        schema={
            "translation_sigma_m": opt("float", 0.0, minimum=0.0, maximum=0.05),
            "rotation_sigma_deg": opt("float", 0.0, minimum=0.0, maximum=5.0),
        },
    ),
}
SCHEMA = {
    "format": Field("int", choices=(1,)),
    "realistic": Field("bool", doc="false: the render's exact images (for diagnosis)"),
    "seed": Field("int", minimum=0, doc="every sensor effect is drawn from this"),
    "zed": Field("dict", schema=_CAMERA),
    "d405": Field("dict", schema=_CAMERA),
}


def load_camera_sensors(path: str | Path = DEFAULT_CAMERAS) -> CameraSensors:
    """Read and validate ``cameras.yaml``; a bad value raises ``ConfigError`` naming the file,
    the key and the reason."""
    doc = load_validated(path, SCHEMA)
    return CameraSensors(doc["realistic"], doc["seed"], _sensor(doc["zed"]), _sensor(doc["d405"]))


__all__ = [
    "DEFAULT_CAMERAS",
    "CameraSensor",
    "CameraSensors",
    "Imager",
    "MountError",
    "StereoDepth",
    "correlated_normal",
    "load_camera_sensors",
    "offset_mounts",
]
