"""A planned joint path with its corners blended: straight pieces joined by circular arcs.

The planner returns a piecewise-linear joint path, every segment collision-checked. Followed
exactly, it makes the arm stop at every waypoint (a corner cannot be turned at speed). Here each
interior waypoint is replaced, where that is allowed, by a circular arc in joint space tangent to
both segments (Kunz and Stilman, "Time-optimal trajectory generation for path following with
bounded acceleration and velocity", RSS 2012): the arc stays within ``max_deviation`` rad
(Euclidean, joint space) of the corner it cuts, and uses at most half of each segment, so the
straight parts left are parts of the checked segments. An ``is_free`` check is run on
configurations along every arc, no further apart than ``resolution`` rad on any joint (the
planner's dense check); a blend that touches is tried at a quarter of the deviation, then a
sixteenth, and otherwise the corner stays a stop. A corner turning by more than
:data:`MAX_BLEND_TURN` is a stop too (nearly a reversal: the arc would be slower than stopping).

The result is a :class:`BlendedPath`: sections between stops (the start, the corners kept, the
end), each a list of :class:`Line` and :class:`Arc` pieces joined with a continuous tangent, with
arc length ``s`` (rad, Euclidean in joint space) as the path parameter. :mod:`time_parameterisation`
times it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

# Largest change of direction (rad) that is blended; sharper corners are stops.
MAX_BLEND_TURN = math.radians(170.0)
# Directions closer than this (rad) continue without an arc or a stop.
COLLINEAR = 1e-7
# A blend that touches is tried again at these fractions of the deviation.
RETRY_FRACTIONS = (1.0, 0.25, 0.0625)


@dataclass(frozen=True)
class Line:
    """``q(s) = start + direction * s`` for ``s`` in ``[0, length]``; ``direction`` is a unit vector."""

    start: np.ndarray
    direction: np.ndarray
    length: float

    def evaluate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, first and second derivatives in ``s`` at the arc lengths ``s`` (one row each)."""
        s = np.asarray(s, dtype=float)[:, None]
        q = self.start + self.direction * s
        dq = np.broadcast_to(self.direction, q.shape).copy()
        return q, dq, np.zeros_like(q)


@dataclass(frozen=True)
class Arc:
    """A circular arc of ``radius`` turning by ``angle`` rad, from ``start`` with tangent ``tangent``
    towards the unit ``normal`` (perpendicular to it, pointing at the centre)."""

    start: np.ndarray
    tangent: np.ndarray
    normal: np.ndarray
    radius: float
    angle: float

    @property
    def length(self) -> float:
        return self.radius * self.angle

    def evaluate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, first and second derivatives in ``s`` at the arc lengths ``s`` (one row each)."""
        th = np.asarray(s, dtype=float)[:, None] / self.radius
        sin, cos = np.sin(th), np.cos(th)
        # Written from the start point (not the centre), so a huge radius loses no precision.
        q = self.start + self.radius * (self.tangent * sin + self.normal * (1.0 - cos))
        dq = self.tangent * cos + self.normal * sin
        ddq = (self.normal * cos - self.tangent * sin) / self.radius
        return q, dq, ddq

    def deviation(self) -> float:
        """Distance (rad) from the corner the arc cuts to the arc's middle."""
        return self.radius * (1.0 / math.cos(self.angle / 2) - 1.0)


Piece = Line | Arc


@dataclass(frozen=True)
class BlendedPath:
    """A path to follow: ``sections`` run from rest to rest; ``waypoints[k]`` are the planned
    waypoints section ``k`` replaces (its stops at either end and the corners it blends);
    ``blended`` and ``stops`` count the interior corners turned at speed and those the arm stops at."""

    sections: list[list[Piece]]
    waypoints: list[list[np.ndarray]]
    blended: int = 0
    stops: int = 0

    @property
    def start(self) -> np.ndarray:
        return self.sections[0][0].start

    @property
    def length(self) -> float:
        return sum(p.length for section in self.sections for p in section)

    def configurations(self, resolution: float) -> np.ndarray:
        """Configurations along the whole path, no further apart than ``resolution`` rad on a joint."""
        rows = [self.start[None, :]]
        for section in self.sections:
            for piece in section:
                n = max(1, math.ceil(piece.length / resolution))
                rows.append(piece.evaluate(np.linspace(0.0, piece.length, n + 1)[1:])[0])
        return np.vstack(rows)


def _arc_free(arc: Arc, is_free: Callable[[np.ndarray], bool], resolution: float) -> bool:
    # The Euclidean step bounds every joint's step.
    n = max(2, math.ceil(arc.length / resolution))
    qs = arc.evaluate(np.linspace(0.0, arc.length, n + 1))[0]
    order = sorted(range(n + 1), key=lambda k: abs(k - n / 2))  # the middle strays furthest: first
    return all(is_free(qs[k]) for k in order)


def _corner_arc(
    corner: np.ndarray, d_in: np.ndarray, d_out: np.ndarray, reach: float, deviation: float
) -> Arc | None:
    """The arc that cuts ``corner`` (incoming unit direction ``d_in``, outgoing ``d_out``) within
    ``deviation`` of it, using at most ``reach`` of each segment; None where that is nothing."""
    turn = math.acos(float(np.clip(d_in @ d_out, -1.0, 1.0)))
    if deviation <= 0.0 or reach <= 0.0:
        return None
    half = turn / 2
    cut = min(reach, deviation * math.sin(half) / (1.0 - math.cos(half)))
    normal = d_out - (d_out @ d_in) * d_in
    normal /= np.linalg.norm(normal)
    radius = cut / math.tan(half)
    return Arc(corner - d_in * cut, d_in, normal, radius, turn)


def blend_corners(
    path: Sequence[Sequence[float]],
    max_deviation: float,
    *,
    is_free: Callable[[np.ndarray], bool] | None = None,
    resolution: float = 0.005,
) -> BlendedPath:
    """``path`` (at least one waypoint) with each interior corner blended within ``max_deviation``
    rad where ``is_free`` holds along the arc (none: every blend is accepted); see the module."""
    qs = [np.asarray(q, dtype=float) for q in path]
    if not qs:
        raise ValueError("an empty path cannot be blended")
    n = qs[0].shape[0]
    if any(q.shape != (n,) for q in qs) or not all(np.all(np.isfinite(q)) for q in qs):
        raise ValueError("every waypoint must have the same number of finite joint values")
    if resolution <= 0:
        raise ValueError("the check resolution must be positive")
    pts = [qs[0]]
    for q in qs[1:]:
        if np.linalg.norm(q - pts[-1]) > 1e-12:
            pts.append(q)
    if len(pts) == 1:
        return BlendedPath([[Line(pts[0], np.zeros(n), 0.0)]], [[pts[0]]])
    lengths = [float(np.linalg.norm(b - a)) for a, b in pairwise(pts)]
    dirs = [(b - a) / ln for (a, b), ln in zip(pairwise(pts), lengths, strict=True)]
    # The arc at each interior corner (None: no arc), and whether the arm stops there.
    arcs: list[Arc | None] = [None] * len(pts)
    stop = [False] * len(pts)
    for i in range(1, len(pts) - 1):
        turn = math.acos(float(np.clip(dirs[i - 1] @ dirs[i], -1.0, 1.0)))
        if turn < COLLINEAR:
            continue
        if turn > MAX_BLEND_TURN or max_deviation <= 0.0:
            stop[i] = True
            continue
        reach = min(lengths[i - 1], lengths[i]) / 2
        for fraction in RETRY_FRACTIONS:
            arc = _corner_arc(pts[i], dirs[i - 1], dirs[i], reach, max_deviation * fraction)
            if arc is not None and (is_free is None or _arc_free(arc, is_free, resolution)):
                arcs[i] = arc
                break
        else:
            stop[i] = True
    sections: list[list[Piece]] = [[]]
    corners: list[list[np.ndarray]] = [[pts[0]]]
    for k in range(len(pts) - 1):
        a, b = pts[k], pts[k + 1]
        cut_start = _cut(arcs[k]) if arcs[k] is not None else 0.0
        cut_end = _cut(arcs[k + 1]) if arcs[k + 1] is not None else 0.0
        remaining = lengths[k] - cut_start - cut_end
        if remaining > 1e-12:
            sections[-1].append(Line(a + dirs[k] * cut_start, dirs[k], remaining))
        corners[-1].append(b)
        if arcs[k + 1] is not None:
            sections[-1].append(arcs[k + 1])
        elif k + 1 < len(pts) - 1 and stop[k + 1]:
            sections.append([])
            corners.append([b])
    return BlendedPath(
        sections,
        corners,
        blended=sum(a is not None for a in arcs),
        stops=sum(stop),
    )


def _cut(arc: Arc) -> float:
    """How much of each segment the arc replaces."""
    return arc.radius * math.tan(arc.angle / 2)


__all__ = ["Arc", "BlendedPath", "Line", "blend_corners"]
