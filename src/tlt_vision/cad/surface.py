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
        parts = [
            value
            for value, _ in (self._segments(points, False), self._boxes(points, False))
            if value is not None
        ]
        return torch.cat(parts, dim=-1).min(dim=-1).values

    def signed_with_gradient(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Signed distance (..., N) and its gradient (..., N, 3) with respect to the points, in
        closed form and without autograd: the corrector and the refinement need both at every
        step. The gradient is that of the nearest primitive (a unit vector, away from its
        surface), as autograd gives for :meth:`signed` almost everywhere."""
        with torch.no_grad():
            nearest = None
            for value, grad in (self._segments(points, True), self._boxes(points, True)):
                if value is None:
                    continue
                if value.shape[-1] > 1:
                    which = value.argmin(dim=-1, keepdim=True)
                    grad = grad.gather(-2, which[..., None].expand(*which.shape, 3))
                    value = value.gather(-1, which)
                value, grad = value[..., 0], grad[..., 0, :]
                if nearest is not None:
                    closer = value < nearest[0]
                    value = torch.where(closer, value, nearest[0])
                    grad = torch.where(closer[..., None], grad, nearest[1])
                nearest = value, grad
            return nearest

    def _segments(
        self, points: torch.Tensor, gradient: bool
    ) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """Each segment primitive's signed distance (..., N, S) and, with ``gradient``, its
        gradient (..., N, S, 3); none without segments. Every gradient is
        ``c_r * radial + c_u * u``: the scalars are chosen per case, and only the last step works
        on vectors."""
        if not self.seg_len.numel():
            return None, None
        rel = points[..., None, :] - self.seg_a.to(points.dtype)  # (..., N, S, 3)
        u = self.seg_u.to(points.dtype)
        s = (rel * u).sum(-1)  # axial coordinate from a
        length, r = self.seg_len.to(points.dtype), self.seg_r.to(points.dtype)
        radial = rel - s[..., None] * u
        # Floored, as is the capsule's distance below: a point on the axis has no radial direction.
        rho = torch.linalg.vector_norm(radial, dim=-1).clamp(min=1e-9)
        # Capsule: the distance to the axis segment minus the radius.
        beyond = s - torch.minimum(torch.clamp(s, min=0.0), length)
        dist = torch.hypot(rho, beyond)
        caps = dist - r
        # Closed cylinder: the standard 2-D (radial, axial) box distance.
        dx = rho - r
        half = s - length / 2
        dz = half.abs() - length / 2
        ox, oz = dx.clamp(min=0), dz.clamp(min=0)
        out = torch.hypot(ox, oz)  # 0 inside, where the gradient below does not divide by it
        cyl = out + torch.maximum(dx, dz).clamp(max=0.0)
        flat = self.seg_flat
        value = torch.where(flat, cyl, caps)
        if not gradient:
            return value, None
        # Capsule: away from the nearest point of the axis segment. Cylinder: outside, from the
        # box's nearest point; inside, away from the nearer face.
        outside, radial_face = out > 0, dx > dz
        cyl_r = torch.where(outside, ox / (out * rho), torch.where(radial_face, 1.0 / rho, 0.0))
        cyl_u = torch.sign(half) * torch.where(outside, oz / out, torch.where(radial_face, 0.0, 1.0))
        c_r, c_u = torch.where(flat, cyl_r, 1.0 / dist), torch.where(flat, cyl_u, beyond / dist)
        return value, c_r[..., None] * radial + c_u[..., None] * u

    def _boxes(self, points: torch.Tensor, gradient: bool) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """Each box primitive's signed distance (..., N, X) and, with ``gradient``, its gradient
        (..., N, X, 3); none without boxes."""
        if not self.box_h.numel():
            return None, None
        rel = points[..., None, :] - self.box_c.to(points.dtype)
        q = rel.abs() - self.box_h.to(points.dtype)
        positive = q.clamp(min=0)
        out = torch.sqrt((positive * positive).sum(-1) + 1e-18)
        deepest = q.max(dim=-1, keepdim=True).values
        value = out + torch.minimum(deepest[..., 0], torch.zeros_like(out))
        if not gradient:
            return value, None
        # Outside, away from the nearest point; inside, away from the nearest face.
        grad = torch.where(deepest > 0, positive / out[..., None], (q >= deepest).to(q.dtype))
        return value, torch.sign(rel) * grad

    def __call__(self, points: torch.Tensor) -> torch.Tensor:
        return self.signed(points).abs()


__all__ = ["SurfaceDistance"]
