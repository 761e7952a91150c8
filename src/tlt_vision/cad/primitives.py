"""Surface primitives (capsule, closed cylinder, box) sampled uniformly by area, with normals.

Every primitive lies along or around its own local axes and is placed by a rotation and an origin;
``sample(n, rng)`` returns ``n`` surface points and their outward normals, uniformly by area.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _frame_for_axis(axis: np.ndarray) -> np.ndarray:
    """A rotation whose z column is ``axis`` (unit)."""
    z = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


@dataclass(frozen=True)
class Segment:
    """A capsule (hemispherical ends) or, with ``flat_ends``, a closed cylinder from ``a`` to ``b``."""

    a: tuple[float, float, float]
    b: tuple[float, float, float]
    radius: float
    flat_ends: bool = False

    def _geometry(self) -> tuple[np.ndarray, float, np.ndarray]:
        a, b = np.asarray(self.a, float), np.asarray(self.b, float)
        length = float(np.linalg.norm(b - a))
        return a, length, _frame_for_axis(b - a)

    def area(self) -> float:
        _, length, _ = self._geometry()
        r = self.radius
        ends = 2 * math.pi * r * r if self.flat_ends else 4 * math.pi * r * r
        return 2 * math.pi * r * length + ends

    def sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        a, length, frame = self._geometry()
        r = self.radius
        side = 2 * math.pi * r * length
        pick = rng.random(n) * self.area()
        pts = np.empty((n, 3))
        nrm = np.empty((n, 3))
        on_side = pick < side
        k = int(on_side.sum())
        phi = rng.random(k) * 2 * math.pi
        nrm[on_side] = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(k)])
        pts[on_side] = nrm[on_side] * r + np.column_stack([np.zeros((k, 2)), rng.random(k) * length])
        m = n - k
        top = rng.random(m) < 0.5
        if self.flat_ends:
            rad = r * np.sqrt(rng.random(m))
            phi = rng.random(m) * 2 * math.pi
            local = np.column_stack([rad * np.cos(phi), rad * np.sin(phi), np.where(top, length, 0.0)])
            normal = np.column_stack([np.zeros((m, 2)), np.where(top, 1.0, -1.0)])
        else:
            v = rng.normal(size=(m, 3))
            v /= np.linalg.norm(v, axis=1, keepdims=True)
            v[:, 2] = np.where(top, np.abs(v[:, 2]), -np.abs(v[:, 2]))
            local = v * r + np.column_stack([np.zeros((m, 2)), np.where(top, length, 0.0)])
            normal = v
        pts[~on_side] = local
        nrm[~on_side] = normal
        return pts @ frame.T + a, nrm @ frame.T


@dataclass(frozen=True)
class Box:
    """An axis-aligned box (in the model frame) of half-extents ``half`` around ``centre``."""

    centre: tuple[float, float, float]
    half: tuple[float, float, float]

    def area(self) -> float:
        hx, hy, hz = self.half
        return 8 * (hx * hy + hy * hz + hx * hz)

    def sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        h = np.asarray(self.half, float)
        face_areas = np.array([h[1] * h[2], h[0] * h[2], h[0] * h[1]])
        axis = rng.choice(3, size=n, p=face_areas / face_areas.sum())
        sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
        pts = (rng.random((n, 3)) * 2 - 1) * h
        nrm = np.zeros((n, 3))
        idx = np.arange(n)
        pts[idx, axis] = sign * h[axis]
        nrm[idx, axis] = sign
        return pts + np.asarray(self.centre, float), nrm


Primitive = Segment | Box


def sample_surface(
    primitives: tuple[Primitive, ...], n: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points and normals on the union of ``primitives``, uniform by area (overlaps counted twice)."""
    areas = np.array([p.area() for p in primitives])
    counts = rng.multinomial(n, areas / areas.sum())
    pts, nrm = [], []
    for prim, c in zip(primitives, counts, strict=True):
        if c:
            p, q = prim.sample(int(c), rng)
            pts.append(p)
            nrm.append(q)
    return np.concatenate(pts), np.concatenate(nrm)


__all__ = ["Box", "Primitive", "Segment", "sample_surface"]
