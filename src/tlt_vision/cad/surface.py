"""Exact distance from points to a CAD model's surface, from its primitives' signed distances.

The certificate and the corrector need, for each observed point, the distance to the nearest point
of the posed model. Sampling the model densely enough for millimetre thresholds on a metre-long
tube would take tens of thousands of points; the primitives' closed-form signed distance functions
give the limit of an infinitely dense sample, exactly and differentiably, in O(N * primitives).
The union's distance is ``|min_i sdf_i|``: exact outside the part (where observed surface points
lie) and a bound inside it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from tlt_vision.cad.primitives import Box, Primitive, Segment


class SurfaceDistance:
    """Callable: points (..., N, 3) in the model frame -> unsigned distance (..., N) to the surface."""

    def __init__(self, primitives: tuple[Primitive, ...], dtype: torch.dtype = torch.float32) -> None:
        seg = [p for p in primitives if isinstance(p, Segment)]
        box = [p for p in primitives if isinstance(p, Box)]
        if len(seg) + len(box) != len(primitives):
            raise TypeError("unknown primitive type")

        def t(values: list, shape: tuple[int, ...]) -> torch.Tensor:
            return torch.tensor(np.asarray(values, dtype=np.float64).reshape(shape), dtype=dtype)

        self.seg_a = t([s.a for s in seg], (len(seg), 3))
        b = t([s.b for s in seg], (len(seg), 3))
        length = torch.linalg.vector_norm(b - self.seg_a, dim=-1)
        self.seg_u = (b - self.seg_a) / length.clamp(min=1e-12)[:, None]
        self.seg_len = length
        self.seg_r = t([s.radius for s in seg], (len(seg),))
        self.seg_flat = torch.tensor([s.flat_ends for s in seg], dtype=torch.bool)
        self.box_c = t([x.centre for x in box], (len(box), 3))
        self.box_h = t([x.half for x in box], (len(box), 3))

    @classmethod
    def stacked(cls, surfaces: Sequence[SurfaceDistance]) -> SurfaceDistance:
        """One surface per batch element: called with points (B, N, 3), element ``b`` is measured
        against ``surfaces[b]``. Elements with fewer primitives are padded with ones a kilometre
        away, which are never the nearest."""
        out = cls.__new__(cls)
        far = 1e3

        def pad(name: str, fill: float | bool, width: int) -> torch.Tensor:
            rows = []
            for s in surfaces:
                value = getattr(s, name)
                extra = value.new_full((width - value.shape[0], *value.shape[1:]), fill)
                rows.append(torch.cat([value, extra]))
            return torch.stack(rows)[:, None]  # (B, 1, width, ...): broadcast over the points

        segments = max(s.seg_len.numel() for s in surfaces)
        boxes = max(s.box_h.shape[0] for s in surfaces)
        out.seg_a, out.seg_u = pad("seg_a", far, segments), pad("seg_u", 0.0, segments)
        out.seg_len, out.seg_r = pad("seg_len", 0.0, segments), pad("seg_r", 0.0, segments)
        out.seg_flat = pad("seg_flat", False, segments)
        out.box_c, out.box_h = pad("box_c", far, boxes), pad("box_h", 0.0, boxes)
        out.batched = True
        return out

    batched = False  # one surface per batch element (:meth:`stacked`)

    def select(self, rows: torch.Tensor) -> SurfaceDistance:
        """The surface for the batch elements ``rows`` of points measured against this one: those
        elements' own of a stacked surface, this one itself otherwise (it serves every element)."""
        if not self.batched:
            return self
        out = SurfaceDistance.__new__(SurfaceDistance)
        for name in ("seg_a", "seg_u", "seg_len", "seg_r", "seg_flat", "box_c", "box_h"):
            setattr(out, name, getattr(self, name)[rows])
        out.batched = True
        return out

    def signed(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance (..., N): negative inside the part."""
        parts = []
        if self.seg_len.numel():
            rel = points[..., None, :] - self.seg_a.to(points.dtype)  # (..., N, S, 3)
            u = self.seg_u.to(points.dtype)
            s = (rel * u).sum(-1)  # axial coordinate from a
            length = self.seg_len.to(points.dtype)
            r = self.seg_r.to(points.dtype)
            radial = rel - s[..., None] * u
            rho = torch.sqrt((radial * radial).sum(-1) + 1e-18)
            # Capsule: distance to the axis segment minus the radius.
            sc = torch.minimum(torch.clamp(s, min=0.0), length)
            caps = torch.sqrt(rho.pow(2) + (s - sc).pow(2) + 1e-18) - r
            # Closed cylinder: the standard 2-D (radial, axial) box distance.
            dx = rho - r
            dz = (s - length / 2).abs() - length / 2
            out = torch.sqrt(dx.clamp(min=0).pow(2) + dz.clamp(min=0).pow(2) + 1e-18)
            cyl = out + torch.minimum(torch.maximum(dx, dz), torch.zeros_like(dx))
            parts.append(torch.where(self.seg_flat, cyl, caps))
        if self.box_h.numel():
            q = (points[..., None, :] - self.box_c.to(points.dtype)).abs() - self.box_h.to(points.dtype)
            outside = torch.sqrt(q.clamp(min=0).pow(2).sum(-1) + 1e-18)
            inside = torch.minimum(q.max(dim=-1).values, torch.zeros_like(outside))
            parts.append(outside + inside)
        return torch.cat(parts, dim=-1).min(dim=-1).values

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        return self.signed(points).abs()


__all__ = ["SurfaceDistance"]
