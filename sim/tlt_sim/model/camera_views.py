"""The twin's cameras as the scene sees them: frames rendered on demand, camera poses and fields of view.

:class:`CameraViews` keeps the offscreen renderers (:class:`tlt_sim.model.cameras.CameraRenderer`)
of one compiled model, made on first use: one with the model's multisampling, the detectors'
look, and one without it for exact depth and segmentation and for cheap frames.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from tlt_sim.model.cameras import CameraRenderer, Frame


class CameraViews:
    """The cameras of ``model`` as ``data`` places them now; ``close`` frees the renderers."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.model, self.data = model, data
        self._renderers: dict[bool, CameraRenderer] = {}  # antialias -> its renderer

    def renderer(self, width: int = 640, height: int = 480, antialias: bool = True) -> CameraRenderer:
        """The offscreen renderer, made on first use with a buffer of at least ``width`` x ``height``
        (remade larger when a bigger frame is asked for, up to the model's offscreen size); one with
        the model's multisampling (``antialias``), another without it when that is asked for."""
        r = self._renderers.get(antialias)
        if r is not None and (width > r.max_width or height > r.max_height):
            width, height = max(width, r.max_width), max(height, r.max_height)
            self._renderers.pop(antialias).close()
            r = None
        if r is None:
            # A small buffer is much cheaper to make with OSMesa than the model's largest.
            limit_w, limit_h = self.model.vis.global_.offwidth, self.model.vis.global_.offheight
            r = self._renderers[antialias] = CameraRenderer(
                self.model, min(max(width, 640), limit_w), min(max(height, 480), limit_h), antialias
            )
        return r

    def render(
        self,
        camera: str | mujoco.MjvCamera,
        width: int = 320,
        height: int = 240,
        depth: bool = True,
        segmentation: bool = True,
        antialias: bool = True,
        rgb: bool = True,
    ) -> Frame:
        """Render ``camera`` (name or free ``mujoco.MjvCamera``) now; see :class:`cameras.Frame`.
        Only the images asked for are made (``rgb``, ``depth``, ``segmentation``). ``antialias``
        (multisampling, the model's setting) is what the vision's detectors were trained on;
        ``False`` is cheaper on the CPU.

        Depth and segmentation always come from a single-sample pass: resolved, a multisampled
        depth buffer gives each pixel the depth of one sample off the pixel's centre (the cloud a
        depth camera would give moved by a third of a pixel: 1-1.5 mm at a metre, which showed as
        that bias in every certified pose), and blended id colours name geoms that are not there."""
        limit_w, limit_h = self.model.vis.global_.offwidth, self.model.vis.global_.offheight
        if not (0 < width <= limit_w and 0 < height <= limit_h):
            raise ValueError(f"frame {width}x{height} exceeds the offscreen buffer {limit_w}x{limit_h}")
        if not (antialias and rgb):
            return self.renderer(width, height, False).render(
                self.data, camera, width, height, depth, segmentation, rgb
            )
        multisampled = self.renderer(width, height, True)
        colour = multisampled.render(self.data, camera, width, height, depth=False, segmentation=False)
        if not (depth or segmentation):
            return colour
        exact = self.renderer(width, height, False)
        frame = exact.render(self.data, camera, width, height, depth, segmentation, rgb=False)
        return dataclasses.replace(frame, rgb=colour.rgb)

    def camera_pose(self, camera: str) -> tuple[np.ndarray, np.ndarray]:
        """Optical frame (x right, y down, z forward) of ``camera`` in the world."""
        cid = self.model.camera(camera).id
        return self.data.cam_xpos[cid].copy(), self.data.cam_xmat[cid].reshape(3, 3) @ np.diag(
            [1.0, -1.0, -1.0]
        )

    def camera_fovy(self, camera: str) -> float:
        return float(self.model.cam_fovy[self.model.camera(camera).id])

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()


__all__ = ["CameraViews"]
