"""Offscreen camera frames of the twin: RGB, depth in metres and instance segmentation.

:class:`CameraRenderer` owns one OpenGL context (OSMesa on the CPU unless ``MUJOCO_GL`` says
otherwise) and renders only when asked. One pass reads colour and depth together; a second pass
with MuJoCo's segmentation colouring gives the geom under every pixel, which
:class:`GeomLabels` turns into instance and class names (a strut's tube and each of its end
fittings are separate instances). Intrinsics follow the pinhole model of the camera's ``fovy``
with square pixels, in OpenCV's pixel-index convention; poses are given for the optical frame
(x right, y down, z forward, as ROS camera frames). The OpenGL back end is chosen in the package's
``__init__`` (OSMesa unless ``MUJOCO_GL`` says otherwise).
"""

from __future__ import annotations

import atexit
import math
import os
import re
import weakref
from dataclasses import dataclass

import mujoco
import numpy as np

# Geom name suffix -> object class (the vision system's classes, as the mission's chamfer thresholds).
_CLASS_PATTERNS = (
    (re.compile(r"/tube(#\d+)?$"), "strut_tube"),
    (re.compile(r"/fitting_[ab]$"), "end_fitting"),
    (re.compile(r"/side_\d$"), "cross_frame"),
    (re.compile(r"/corner_\d$"), "corner_joint"),
    (re.compile(r"/rivet_\w+(#\d+)?$"), "rivet"),
    (re.compile(r"/tag$"), "apriltag"),
)


@dataclass(frozen=True)
class Intrinsics:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def intrinsics(fovy_deg: float, width: int, height: int) -> Intrinsics:
    """Pinhole intrinsics of a MuJoCo camera (vertical field of view ``fovy_deg``, square pixels)."""
    fy = (height / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    return Intrinsics(width, height, fy, fy, (width - 1) / 2.0, (height - 1) / 2.0)


class GeomLabels:
    """Instance and class of every geom, from the names the generator gives them."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.instance_names: list[str] = []
        self.classes: list[str] = []
        index: dict[str, int] = {}
        self.geom_instance = np.full(model.ngeom, -1, dtype=np.int32)
        for g in range(model.ngeom):
            name = model.geom(g).name or model.body(model.geom_bodyid[g]).name
            cls = next((c for pattern, c in _CLASS_PATTERNS if pattern.search(name)), "machine")
            instance = name.split("#")[0]
            if instance not in index:
                index[instance] = len(self.instance_names)
                self.instance_names.append(instance)
                self.classes.append(cls)
            self.geom_instance[g] = index[instance]


@dataclass
class Frame:
    """One rendered camera frame. ``segmentation`` holds instance ids (-1: nothing)."""

    camera: str
    time: float
    rgb: np.ndarray | None  # (h, w, 3) uint8; None when not asked for
    depth: np.ndarray | None  # (h, w) float32 metres along the optical axis, 0 where nothing
    segmentation: np.ndarray | None  # (h, w) int32 instance ids
    intrinsics: Intrinsics
    position: np.ndarray  # optical frame origin in the world
    rotation: np.ndarray  # optical frame axes (columns) in the world
    labels: GeomLabels

    def instances(self) -> dict[str, int]:
        """Instance name -> visible pixel count."""
        if self.segmentation is None:
            raise ValueError("this frame was rendered without segmentation")
        ids, counts = np.unique(self.segmentation[self.segmentation >= 0], return_counts=True)
        return {self.labels.instance_names[i]: int(n) for i, n in zip(ids, counts, strict=True)}

    def mask(self, instance: str) -> np.ndarray:
        if self.segmentation is None:
            raise ValueError("this frame was rendered without segmentation")
        return self.segmentation == self.labels.instance_names.index(instance)

    def class_of(self, instance: str) -> str:
        return self.labels.classes[self.labels.instance_names.index(instance)]


_OPEN: weakref.WeakSet = weakref.WeakSet()


def _gl_context(width: int, height: int):
    """A GL context of the back end ``MUJOCO_GL`` names (OSMesa by default), chosen here rather
    than by ``mujoco.GLContext``, which froze its choice when mujoco was first imported."""
    backend = os.environ.get("MUJOCO_GL", "osmesa").lower()
    if backend == "osmesa":
        from mujoco.osmesa import GLContext
    elif backend == "egl":
        from mujoco.egl import GLContext
    else:
        from mujoco.glfw import GLContext
    return GLContext(width, height)


@atexit.register
def _close_all() -> None:
    # GL contexts freed by the garbage collector at interpreter exit fail noisily; free them first.
    for renderer in list(_OPEN):
        renderer.close()


class CameraRenderer:
    """Offscreen renderer bound to one model; ``close`` frees the GL context.

    ``antialias`` (the default) renders with the model's multisampling (``visual/quality
    offsamples``), as the vision's detectors were trained on. Without it a frame costs markedly
    less CPU on OSMesa and segmentation edges are exact (multisampling blends the id colours
    of neighbouring geoms at their borders into ids of geoms that are not there), but the frames
    differ at every edge from what those detectors learned on.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        max_width: int | None = None,
        max_height: int | None = None,
        antialias: bool = True,
    ) -> None:
        self.model = model
        self.antialias = antialias
        self.max_width = max_width or model.vis.global_.offwidth
        self.max_height = max_height or model.vis.global_.offheight
        self._gl = _gl_context(self.max_width, self.max_height)
        self._gl.make_current()
        # MjrContext takes its sample count from the model: lend it ours for the moment it is made.
        samples = model.vis.quality.offsamples
        if not antialias:
            model.vis.quality.offsamples = 0
        try:
            self._ctx = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        finally:
            model.vis.quality.offsamples = samples
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._ctx)
        self._scene = mujoco.MjvScene(model, maxgeom=max(1000, 2 * model.ngeom))
        self.option = mujoco.MjvOption()
        self.option.sitegroup[:] = 0  # sites are bookkeeping points, not things a camera sees
        for flag in (mujoco.mjtRndFlag.mjRND_REFLECTION, mujoco.mjtRndFlag.mjRND_SKYBOX):
            self._scene.flags[flag] = False  # CPU rendering: these cost most and tell vision nothing
        # Shadows cost as much; they are drawn only where a light casts them (a hard, low sun:
        # tlt_sim.model.lighting).
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = bool(np.any(model.light_castshadow))
        self.labels = GeomLabels(model)
        extent = model.stat.extent
        self._near, self._far = model.vis.map.znear * extent, model.vis.map.zfar * extent
        _OPEN.add(self)

    def close(self) -> None:
        if self._gl is not None:
            self._ctx.free()
            self._gl.free()
            self._gl = None

    def _camera(self, camera: str | mujoco.MjvCamera) -> tuple[mujoco.MjvCamera, float]:
        if isinstance(camera, mujoco.MjvCamera):
            return camera, float(self.model.vis.global_.fovy)
        cam_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cam_id < 0:
            raise KeyError(f"no camera named {camera!r}")
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        cam.fixedcamid = cam_id
        return cam, float(self.model.cam_fovy[cam_id])

    def render(
        self,
        data: mujoco.MjData,
        camera: str | mujoco.MjvCamera,
        width: int,
        height: int,
        depth: bool = True,
        segmentation: bool = True,
        rgb: bool = True,
    ) -> Frame:
        """Render ``camera`` (a camera name, or a free ``MjvCamera``) at ``width`` x ``height``.
        Only the images asked for are made: with neither ``rgb`` nor ``depth`` the colour pass is
        skipped altogether (``Frame.rgb`` and ``Frame.depth`` are then None)."""
        if self._gl is None:
            raise RuntimeError("renderer is closed")
        if not (0 < width <= self.max_width and 0 < height <= self.max_height):
            raise ValueError(f"frame {width}x{height} exceeds the buffer {self.max_width}x{self.max_height}")
        cam, fovy = self._camera(camera)
        self._gl.make_current()
        viewport = mujoco.MjrRect(0, 0, width, height)
        mujoco.mjv_updateScene(
            self.model, data, self.option, None, cam, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        colour = np.empty((height, width, 3), dtype=np.uint8) if rgb else None
        zbuf = np.empty((height, width), dtype=np.float32) if depth else None
        if rgb or depth:
            mujoco.mjr_render(viewport, self._scene, self._ctx)
            mujoco.mjr_readPixels(colour, zbuf, viewport, self._ctx)
        if colour is not None:
            colour = np.flipud(colour)
        metres = None
        if zbuf is not None:
            zbuf = np.flipud(zbuf)
            metres = (self._near / (1.0 - zbuf * (1.0 - self._near / self._far))).astype(np.float32)
            metres[zbuf >= 1.0] = 0.0
        seg = self._segment(viewport, width, height) if segmentation else None
        if isinstance(camera, str):
            cam_id = cam.fixedcamid
            position = data.cam_xpos[cam_id].copy()
            rotation = data.cam_xmat[cam_id].reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
            name = camera
        else:
            position, rotation, name = self._free_camera_pose(), np.eye(3), "free"
        return Frame(
            name,
            float(data.time),
            colour,
            metres,
            seg,
            intrinsics(fovy, width, height),
            position,
            rotation,
            self.labels,
        )

    def _segment(self, viewport: mujoco.MjrRect, width: int, height: int) -> np.ndarray:
        scn = self._scene
        scn.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
        scn.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        try:
            mujoco.mjr_render(viewport, scn, self._ctx)
            # The colour is (scene geom index + 1) in little-endian RGB, 0 where nothing was drawn:
            # read it into the low three bytes of a 32-bit word and it is the number itself.
            words = np.zeros((height, width, 4), dtype=np.uint8)
            ids = np.empty((height, width, 3), dtype=np.uint8)
            mujoco.mjr_readPixels(ids, None, viewport, self._ctx)
        finally:
            scn.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = False
            scn.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = False
        words[..., :3] = ids
        code = words.view("<u4")[..., 0]
        none = scn.ngeom + 1
        np.minimum(code, none, out=code)  # anything not a scene geom reads as nothing
        # lookup[code]: 0 and ngeom + 1 -> -1; k -> instance of scene geom k - 1.
        lookup = np.full(scn.ngeom + 2, -1, dtype=np.int32)
        # Only the scene geoms that show in the frame (a few dozen of some hundreds): reading a
        # scene geom from Python costs microseconds each.
        for k in np.flatnonzero(np.bincount(code.ravel(), minlength=none + 1)[1:none]).tolist():
            g = scn.geoms[k]
            if g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                lookup[k + 1] = self.labels.geom_instance[g.objid]
        return lookup[np.flipud(code)]

    def _free_camera_pose(self) -> np.ndarray:
        return np.asarray(self._scene.camera[0].pos, dtype=float).copy()


__all__ = ["CameraRenderer", "Frame", "GeomLabels", "Intrinsics", "intrinsics"]
