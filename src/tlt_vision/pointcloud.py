"""Instance masks applied to RGB and depth, back-projected to a point cloud in the camera frame.

Reads a boolean mask (H, W), a depth image (H, W) in metres along the optical axis (0, NaN or inf
for "no depth", as the twin and the RealSense/ZED drivers give it), optionally the RGB image
(H, W, 3), and pinhole intrinsics ``fx, fy, cx, cy`` in the OpenCV convention (pixel (u, v) has its
centre at column u, row v; x right, y down, z forward):
``x = (u - cx) z / fx``, ``y = (v - cy) z / fy``.

Pixels on a mask's border are dropped first (``erode``, 1 px by default): their depth mixes the
part and what lies behind it ("flying pixels", on the twin's renders as on real depth cameras), and
on a small part they are a large share of the mask; one such pixel a metre behind the part is
enough to fail its certificate. Given the part's size (``extent``), pixels whose depth lies further
than that from the mask's median depth are dropped too: a learned mask strays a pixel or two past
a part's outline, onto whatever lies behind it (for Mask R-CNN's end-fitting masks, a sizeable
share of their pixels, up to metres behind the fitting), which no point of the part can be.

A learned mask also strays onto what lies behind the part within that span: a diagonal tube's
mask can take in a few pixels of the floor behind its end, enough to pull C-3PO's tube
centimetres along its axis and fail a good strut. Such pixels make pieces of the cloud no
chain of close points joins to the part: :func:`detached_pieces` finds them (a cloud is one
rigid part, seen whole or cut by what stands in front of it, and each piece of it is large).
A compact part (an end fitting, a corner joint) is rarely cut so, but its learned mask often takes
in a neighbour of its kind that touches it in the image: fittings side by side in a rack, the
joints of a bay one behind the other. For the classes in ``largest_only`` only the largest piece
is kept.

It never raises on bad data and never returns points it could not trust: an empty mask, a mask
with no valid depth, too few points, or images whose shapes disagree give a :class:`MaskedCloud`
with no points and ``reason`` saying which.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from tlt_vision.depth_noise import window_median

MIN_POINTS = 32


class PinholeIntrinsics(Protocol):
    fx: float
    fy: float
    cx: float
    cy: float


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels (the twin's ``tlt_sim.model.cameras.Intrinsics`` fits too)."""

    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_matrix(cls, k: np.ndarray) -> Intrinsics:
        k = np.asarray(k, dtype=float)
        return cls(float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]))


@dataclass(frozen=True)
class MaskedCloud:
    """Points (N, 3) in metres, their colours (N, 3) uint8 or None, and why it failed (or "")."""

    points: np.ndarray
    colours: np.ndarray | None
    mask_pixels: int
    reason: str = ""

    @property
    def ok(self) -> bool:
        return not self.reason


@dataclass(frozen=True)
class Detached:
    """Which pieces of a cloud are not the part: those that no chain of points at most ``link`` (m)
    apart joins to the rest and that hold under ``below`` of its points, or, for the classes in
    ``largest_only``, every piece but the largest. ``links`` gives a class a link of its own:
    pieces of a small part's neighbours lie nearer than a tube's (rivets in a feeder 13 mm apart)."""

    link: float = 0.02
    below: float = 0.05
    largest_only: tuple[str, ...] = ()
    links: tuple[tuple[str, float], ...] = ()

    def link_of(self, object_class: str | None) -> float:
        """The link (m) of ``object_class``'s clouds."""
        return dict(self.links).get(object_class, self.link)


DEFAULT_DETACHED = Detached()


def detached_pieces(points: np.ndarray, detached: Detached, object_class: str | None = None) -> np.ndarray:
    """Boolean (N,): the points of ``points`` (N, 3), a cloud of ``object_class``, in detached
    pieces."""
    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    if n == 0:
        return np.zeros(0, dtype=bool)
    # Pairs from a k-d tree: an N x N distance matrix is far slower for a tube's hundreds of points.
    pairs = cKDTree(p).query_pairs(detached.link_of(object_class), output_type="ndarray")
    links = coo_matrix((np.ones(len(pairs), dtype=bool), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(links, directed=False)
    sizes = np.bincount(label)
    others = label != np.argmax(sizes)
    return others if object_class in detached.largest_only else others & (sizes[label] < detached.below * n)


def _failed(reason: str, mask_pixels: int = 0) -> MaskedCloud:
    return MaskedCloud(np.zeros((0, 3), dtype=np.float32), None, mask_pixels, reason)


def masked_point_cloud(
    mask: np.ndarray,
    depth: np.ndarray | None,
    intrinsics: PinholeIntrinsics,
    rgb: np.ndarray | None = None,
    min_points: int = MIN_POINTS,
    depth_range: tuple[float, float] = (0.05, 20.0),
    max_points: int | None = None,
    erode: int = 1,
    extent: float | None = None,
    smooth: int = 0,
) -> MaskedCloud:
    """Back-project the masked pixels with valid depth; ``max_points`` keeps that many, evenly
    spaced in the mask's raster order;
    ``extent`` (m), the part's size, drops pixels further than that from the median depth;
    ``smooth`` (pixels, odd), when over 1, gives each point the median depth of the valid pixels
    in that square about it (:func:`tlt_vision.depth_noise.window_median`)."""
    if depth is None:
        return _failed("no depth image")
    mask = np.asarray(mask)
    depth = np.asarray(depth)
    if mask.ndim != 2 or depth.shape != mask.shape:
        return _failed(f"mask shape {mask.shape} does not match depth shape {depth.shape}")
    if rgb is not None and np.asarray(rgb).shape[:2] != mask.shape:
        return _failed(f"RGB shape {np.asarray(rgb).shape} does not match mask shape {mask.shape}")
    if not (intrinsics.fx > 0 and intrinsics.fy > 0):
        return _failed(f"invalid intrinsics fx={intrinsics.fx}, fy={intrinsics.fy}")
    sel = mask.astype(bool)
    pixels = np.count_nonzero(sel)
    if pixels == 0:
        return _failed("empty mask: part not in view")
    # Only the mask's box, with a pixel of margin for the erosion to see the mask's edge: a part
    # is a small share of the frame, and a frame's thirty parts each went over the whole of it.
    rows, cols = np.flatnonzero(sel.any(1)), np.flatnonzero(sel.any(0))
    top, left = max(int(rows[0]) - 1, 0), max(int(cols[0]) - 1, 0)
    box = np.s_[top : int(rows[-1]) + 2, left : int(cols[-1]) + 2]
    sel, depth = sel[box], depth[box]
    core = (
        cv2.erode(sel.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=erode).astype(bool)
        if erode
        else sel
    )
    with np.errstate(invalid="ignore"):
        valid = core & np.isfinite(depth) & (depth >= depth_range[0]) & (depth <= depth_range[1])
    if extent is not None and valid.any():
        valid &= np.abs(depth - np.median(depth[valid])) <= extent
    n = int(valid.sum())
    if n == 0 and core.any():
        return _failed(f"no depth: none of the {pixels} mask pixels has a valid depth", pixels)
    if n == 0:
        return _failed(f"too few points: the mask of {pixels} px has no pixel off its border", pixels)
    if n < min_points:
        return _failed(f"too few points: {n} with valid depth < {min_points}", pixels)
    v, u = np.nonzero(valid)
    if max_points is not None and n > max_points:
        # Evenly spaced, not drawn: every region of the mask kept as densely as the rest, and the
        # same mask always the same points; on held-out sets it certifies at least as many views
        # as a random draw.
        pick = np.linspace(0, n - 1, max_points).round().astype(np.intp)
        v, u = v[pick], u[pick]
    z = window_median(depth, valid, v, u, smooth) if smooth > 1 else depth[v, u].astype(np.float64)
    v, u = v + top, u + left
    pts = back_project(u, v, z, intrinsics).astype(np.float32)
    colours = np.asarray(rgb)[v, u].astype(np.uint8) if rgb is not None else None
    return MaskedCloud(pts, colours, pixels)


def back_project(u: np.ndarray, v: np.ndarray, z: np.ndarray, intrinsics: PinholeIntrinsics) -> np.ndarray:
    """Camera-frame points (N, 3) of pixels (``u`` column, ``v`` row) seen at depths ``z``."""
    return np.stack([(u - intrinsics.cx) * z / intrinsics.fx, (v - intrinsics.cy) * z / intrinsics.fy, z], 1)


def project(points: np.ndarray, intrinsics: PinholeIntrinsics) -> np.ndarray:
    """Pixel coordinates (N, 2) ``(u, v)`` of camera-frame points (N, 3); the inverse of
    :func:`back_project`."""
    p = np.asarray(points, dtype=float)
    return np.stack(
        [
            p[:, 0] / p[:, 2] * intrinsics.fx + intrinsics.cx,
            p[:, 1] / p[:, 2] * intrinsics.fy + intrinsics.cy,
        ],
        1,
    )


def pixels_in_image(
    points: np.ndarray, intrinsics: PinholeIntrinsics, shape: tuple[int, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """Where camera-frame ``points`` (N, 3) in front of the camera land in an image of ``shape``
    (height, width): their rounded pixels (M, 2) ``(u, v)`` and the indices (M,) of those points."""
    p = np.asarray(points, dtype=float)
    ahead = np.flatnonzero(p[:, 2] > 1e-6)
    uv = np.rint(project(p[ahead], intrinsics)).astype(np.int64)
    h, w = shape[:2]
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    return uv[inside], ahead[inside]


__all__ = ["MIN_POINTS", "Intrinsics", "MaskedCloud", "masked_point_cloud", "pixels_in_image", "project"]
