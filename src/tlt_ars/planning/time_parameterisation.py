"""Time parameterisation of joint paths under the UR10e's velocity and acceleration limits.

Reads a path, either a list of waypoints (rad) followed exactly with a stop at each, or a
:class:`~tlt_ars.planning.blended_path.BlendedPath` (corners blended by circular arcs), and
per-joint limits; writes a trajectory as a list of :class:`TrajectoryPoint` (time from start,
positions, velocities, accelerations), the shape of a ``trajectory_msgs/JointTrajectory``.

A straight piece between two stops is followed with all joints synchronised: the path parameter
follows a trapezoidal (or triangular) velocity profile whose peak velocity and acceleration are the
largest any joint allows, so the limiting joint runs at its limit. That is the time-optimal motion
along the joint-space line (:func:`straight_line_duration`), in closed form.

A section of lines and arcs between two stops is timed by reachability analysis (TOPP-RA: Pham
and Pham, "A new approach to time-optimal path parameterization based on reachability analysis",
IEEE T-RO 2018) on a grid along the path, written here in numpy for the case of per-joint box
limits, where every step is a closed form: with ``x = (ds/dt)^2`` and ``u = d2s/dt2`` constant on
each grid interval, every limit is linear in ``(u, x)``; a backward pass finds the largest speed
from which the end can still be reached at rest, and a forward pass takes the largest
acceleration that stays within it. Each interval's ``u`` is checked against the limits at both
of its ends (the "interpolation" scheme), which is exact along a line (constant tangent). Along an
arc the tangent turns between the grid points; the limits there are tightened by the most the
velocity and acceleration can exceed their values at the interval's ends (a bound from the arc's
curvature and the grid step), so that every joint is within its limits at every instant, not only
at the grid points.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from tlt_ars.planning.blended_path import Arc, BlendedPath, Line, Piece

# Largest grid step along a section (rad of joint-space path) and largest turn of an arc between
# two grid points (rad): the step bounds how much time the grid costs against the continuous
# optimum, the turn how far the limits along an arc are tightened.
GRID_STEP = 0.05
ARC_GRID_TURN = 0.02
# Fewest grid intervals on a piece: on a short line between tight arcs the arm speeds up and slows
# down again, which one interval (one constant acceleration) cannot do.
PIECE_INTERVALS = 8
# Limits are applied this much tighter, so that rounding never puts a sample over them.
_ROUNDING = 1e-9


@dataclass(frozen=True)
class TrajectoryPoint:
    """One sample: ``t`` seconds from the start; positions ``q``, velocities ``qd``, accelerations ``qdd``."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


@dataclass(frozen=True)
class _Segment:
    q0: np.ndarray
    dq: np.ndarray
    t0: float
    ta: float  # acceleration (and deceleration) time
    tc: float  # cruise time
    vmax: float  # peak ds/dt
    amax: float  # d2s/dt2 during the ramps

    @property
    def duration(self) -> float:
        return 2 * self.ta + self.tc

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at ``t`` seconds into the segment."""
        t = min(max(t, 0.0), self.duration)
        a, v, ta, tc = self.amax, self.vmax, self.ta, self.tc
        if t < ta:
            s, sd, sdd = 0.5 * a * t * t, a * t, a
        elif t <= ta + tc:
            s, sd, sdd = 0.5 * a * ta * ta + v * (t - ta), v, 0.0
        else:
            tr = self.duration - t
            s, sd, sdd = 1.0 - 0.5 * a * tr * tr, a * tr, -a
        if self.duration <= 0.0:
            s, sd, sdd = 1.0, 0.0, 0.0
        return self.q0 + self.dq * s, self.dq * sd, self.dq * sdd


def _check_limits(vel: Sequence[float], acc: Sequence[float], n: int) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vel, dtype=float)
    a = np.asarray(acc, dtype=float)
    if v.shape != (n,) or a.shape != (n,):
        raise ValueError(f"expected {n} velocity and acceleration limits, got {v.shape[0]} and {a.shape[0]}")
    if np.any(v <= 0) or np.any(a <= 0) or not np.all(np.isfinite(v)) or not np.all(np.isfinite(a)):
        raise ValueError("velocity and acceleration limits must be positive and finite")
    return v, a


def _segment(q0: np.ndarray, q1: np.ndarray, t0: float, vel: np.ndarray, acc: np.ndarray) -> _Segment:
    dq = q1 - q0
    moving = np.abs(dq) > 1e-12
    if not np.any(moving):
        return _Segment(q0, dq, t0, 0.0, 0.0, 0.0, 0.0)
    # Along the line q = q0 + s dq each joint allows |ds/dt| <= v_i/|dq_i|, |d2s/dt2| <= a_i/|dq_i|.
    vmax = float(np.min(vel[moving] / np.abs(dq[moving])))
    amax = float(np.min(acc[moving] / np.abs(dq[moving])))
    ta = vmax / amax
    if amax * ta * ta >= 1.0:  # never reaches vmax: triangular profile
        ta = math.sqrt(1.0 / amax)
        vmax = amax * ta
        tc = 0.0
    else:
        tc = (1.0 - amax * ta * ta) / vmax
    return _Segment(q0, dq, t0, ta, tc, vmax, amax)


def straight_line_duration(
    q0: Sequence[float], q1: Sequence[float], velocity: Sequence[float], acceleration: Sequence[float]
) -> float:
    """Minimum time (s) to move from rest at ``q0`` to rest at ``q1`` along the joint-space line."""
    a = np.asarray(q0, dtype=float)
    b = np.asarray(q1, dtype=float)
    v, acc = _check_limits(velocity, acceleration, a.shape[0])
    return _segment(a, b, 0.0, v, acc).duration


class _ToppSection:
    """A section of lines and arcs from rest to rest, timed by reachability analysis (module doc)."""

    def __init__(self, pieces: Sequence[Piece], vel: np.ndarray, acc: np.ndarray) -> None:
        self.pieces = list(pieces)
        s0, s1, owner = [], [], []
        for j, piece in enumerate(self.pieces):
            m = math.ceil(piece.length / GRID_STEP)
            if isinstance(piece, Arc):
                m = max(m, math.ceil(piece.angle / ARC_GRID_TURN))
            edges = np.linspace(0.0, piece.length, max(m, PIECE_INTERVALS) + 1)
            s0.append(edges[:-1])
            s1.append(edges[1:])
            owner.append(np.full(len(edges) - 1, j))
        self.s0 = np.concatenate(s0)  # each interval's start and end, along its own piece
        self.s1 = np.concatenate(s1)
        self.owner = np.concatenate(owner)
        n = vel.shape[0]
        count = self.s0.shape[0]
        dq0, ddq0, dq1, ddq1 = (np.empty((count, n)) for _ in range(4))
        turn = np.zeros(count)  # the arc's turn over the interval (0 on a line)
        swing = np.zeros((count, n))  # per joint: the amplitude of the tangent's turn on an arc
        for j, piece in enumerate(self.pieces):
            k = self.owner == j
            _, dq0[k], ddq0[k] = piece.evaluate(self.s0[k])
            _, dq1[k], ddq1[k] = piece.evaluate(self.s1[k])
            if isinstance(piece, Arc):
                turn[k] = (self.s1[k] - self.s0[k]) / piece.radius
                swing[k] = np.hypot(piece.tangent, piece.normal)
        delta = self.s1 - self.s0
        self.delta = delta

        # Between the ends of an arc interval a joint's tangent component (a sinusoid in the turn)
        # exceeds the larger of its end values by at most turn^2/8 times its amplitude, and its
        # acceleration exceeds the line between its end values by at most turn^2/8 * amplitude *
        # 6 |a| (|ds/dt|^2 / radius and |d2s/dt2| are each at most |a|, the norm of the limits).
        bulge = (turn**2 / 8.0)[:, None] * swing
        a_eff = acc * (1.0 - _ROUNDING) - bulge * 6.0 * float(np.linalg.norm(acc))
        if np.any(a_eff <= 0.0):
            raise ValueError("the grid is too coarse for the arcs of this path")
        tangent_max = np.maximum(np.abs(dq0), np.abs(dq1)) + bulge
        with np.errstate(divide="ignore"):
            x_vel = np.min(
                np.where(tangent_max > 0, (vel * (1.0 - _ROUNDING) / tangent_max) ** 2, np.inf), axis=1
            )

        # Each joint's acceleration at each end of an interval, as -gamma <= alpha u + beta x <= gamma
        # with x = x_k (ds/dt squared at the interval's start), u the interval's d2s/dt2 and
        # x_{k+1} = x_k + 2 delta u; then u within S x -+ W where alpha is not 0, and |beta| x <=
        # gamma where it is.
        two_d = (2.0 * delta)[:, None]
        alpha = np.hstack([dq0, dq1 + two_d * ddq1])
        beta = np.hstack([ddq0, ddq1])
        gamma = np.hstack([a_eff, a_eff])
        scale = np.max(np.abs(alpha), axis=1, keepdims=True)
        moving = np.abs(alpha) > 1e-12 * scale
        safe = np.where(moving, alpha, 1.0)
        S = np.where(moving, -beta / safe, 0.0)
        W = np.where(moving, gamma / np.abs(safe), np.inf)

        # The largest x_k from which a u within the limits exists, whatever comes after (the
        # smallest is 0: x = 0, u = 0 meets every limit): the velocity limit, the joints whose
        # acceleration does not depend on u, every lower bound of u against every upper bound,
        # and x_{k+1} >= 0 (u >= -x / (2 delta)) against every upper bound.
        x_max = x_vel.copy()
        with np.errstate(divide="ignore", invalid="ignore"):
            fixed = ~moving & (np.abs(beta) > 0)
            x_max = np.minimum(x_max, np.where(fixed, gamma / np.abs(beta), np.inf).min(axis=1))
            c = S[:, :, None] - S[:, None, :]
            pair = moving[:, :, None] & moving[:, None, :] & (c > 0)
            d = W[:, :, None] + W[:, None, :]
            x_max = np.minimum(x_max, np.where(pair, d / np.where(pair, c, 1.0), np.inf).min(axis=(1, 2)))
            c_end = -1.0 / two_d - S
            fits = moving & (c_end > 0)
            x_max = np.minimum(x_max, np.where(fits, W / np.where(fits, c_end, 1.0), np.inf).min(axis=1))
            # u <= (X - x) / (2 delta), X the largest x_{k+1} still controllable and within the
            # velocity limit, against every lower bound of u: x <= A X + B.
            c_next = S + 1.0 / two_d
            step = moving & (c_next > 0)
            a_step = np.where(step, 1.0 / (two_d * np.where(step, c_next, 1.0)), 0.0)
            b_step = np.where(step, W / np.where(step, c_next, 1.0), np.inf)

        # Backward: the controllable sets [0, reach[k]]; at the end, at rest. Then forward: the
        # largest acceleration that stays controllable. (Plain floats: a step is a dozen rows,
        # where numpy's per-call cost would dominate.)
        # A row that does not apply has slope 0 and offset +inf.
        a_rows, b_rows, s_rows, w_rows = a_step.tolist(), b_step.tolist(), S.tolist(), W.tolist()
        caps, vcaps, gaps = x_max.tolist(), x_vel.tolist(), (2.0 * delta).tolist()
        reach = [0.0] * (count + 1)
        for k in range(count - 1, -1, -1):
            nxt = min(reach[k + 1], vcaps[k])
            reach[k] = min([caps[k]] + [a * nxt + b for a, b in zip(a_rows[k], b_rows[k], strict=True)])
        if reach[0] < 0.0:
            raise ValueError("no motion along this path meets the limits")
        xs = [0.0] * (count + 1)
        for k in range(count):
            xk, gap, nxt = xs[k], gaps[k], min(reach[k + 1], vcaps[k])
            u = min([(nxt - xk) / gap] + [sk * xk + wk for sk, wk in zip(s_rows[k], w_rows[k], strict=True)])
            xs[k + 1] = min(max(xk + gap * u, 0.0), nxt)
        x = np.asarray(xs)
        self.u = (x[1:] - x[:-1]) / (2.0 * delta)
        self.sd = np.sqrt(x)
        speed = self.sd[:-1] + self.sd[1:]
        if np.any(speed <= 0.0):
            raise ValueError("the path cannot be followed: a grid interval has no speed")
        self.times = np.concatenate([[0.0], np.cumsum(2.0 * delta / speed)])
        self.duration = float(self.times[-1])

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at ``t`` seconds into the section."""
        t = min(max(t, 0.0), self.duration)
        k = int(np.searchsorted(self.times, t, side="right")) - 1
        k = min(max(k, 0), len(self.delta) - 1)
        tau = t - self.times[k]
        u = float(self.u[k])
        sd = max(float(self.sd[k]) + u * tau, 0.0)
        s = min(float(self.s0[k]) + float(self.sd[k]) * tau + 0.5 * u * tau * tau, float(self.s1[k]))
        q, dq, ddq = self.pieces[int(self.owner[k])].evaluate(np.array([s]))
        return q[0], dq[0] * sd, dq[0] * u + ddq[0] * sd * sd


class Trajectory:
    """A time-parameterised path: sample it anywhere, or list points at a fixed period."""

    def __init__(self, sections: Sequence[_Segment | _ToppSection]) -> None:
        self._sections = list(sections)
        self.duration = float(sum(s.duration for s in self._sections))
        self._starts = np.cumsum([0.0] + [s.duration for s in self._sections])

    def sample(self, t: float) -> TrajectoryPoint:
        t = min(max(t, 0.0), self.duration)
        k = int(np.searchsorted(self._starts, t, side="right") - 1)
        k = min(max(k, 0), len(self._sections) - 1)
        q, qd, qdd = self._sections[k].sample(t - self._starts[k])
        return TrajectoryPoint(t, q, qd, qdd)

    def points(self, period: float) -> list[TrajectoryPoint]:
        """Samples every ``period`` seconds plus every stop and the end, in time order."""
        if period <= 0:
            raise ValueError("sample period must be positive")
        stops = np.asarray(self._starts, dtype=float)
        grid = np.arange(0.0, self.duration, period)
        # A grid time a hair from a stop would make two points the nanosecond stamps of a
        # JointTrajectory cannot tell apart (the controller refuses points not after the previous).
        apart = np.min(np.abs(grid[:, None] - stops[None, :]), axis=1) >= 1e-6
        return [self.sample(t) for t in sorted(set(grid[apart].tolist()) | set(stops.tolist()))]

    def stops(self) -> list[TrajectoryPoint]:
        """One point per stop (at rest): the start, every corner not blended, the end."""
        return [self.sample(float(t)) for t in self._starts]


def _sections(
    pieces: list[Piece], waypoints: list[np.ndarray], vel: np.ndarray, acc: np.ndarray
) -> list[_Segment | _ToppSection]:
    """One section of a blended path, or the stops at its waypoints where they are faster."""
    if len(pieces) == 1 and isinstance(pieces[0], Line):
        line = pieces[0]
        return [_segment(line.start, line.start + line.direction * line.length, 0.0, vel, acc)]
    stops = [_segment(q0, q1, 0.0, vel, acc) for q0, q1 in pairwise(waypoints)]
    try:
        blended = _ToppSection(pieces, vel, acc)
    except ValueError:  # a degenerate section (none is known): the planned corners always serve
        return stops
    # An arc cut from short segments is tight, and at a sharp corner it can take longer than
    # stopping: then the section stops at its corners, as planned.
    return [blended] if blended.duration <= sum(s.duration for s in stops) else stops


def time_parameterise(
    path: Sequence[Sequence[float]] | BlendedPath, velocity: Sequence[float], acceleration: Sequence[float]
) -> Trajectory:
    """Time-parameterise ``path``, starting and ending at rest: waypoints (at least one) are followed
    on straight lines with a stop at each; a :class:`BlendedPath` stops only where it says, except
    that a section whose corners are faster stopped at than blended is followed as planned, with
    the stops."""
    if isinstance(path, BlendedPath):
        v, a = _check_limits(velocity, acceleration, path.start.shape[0])
        return Trajectory(
            [
                s
                for pieces, wps in zip(path.sections, path.waypoints, strict=True)
                for s in _sections(pieces, wps, v, a)
            ]
        )
    qs = [np.asarray(q, dtype=float) for q in path]
    if not qs:
        raise ValueError("an empty path cannot be time-parameterised")
    n = qs[0].shape[0]
    if any(q.shape != (n,) for q in qs) or not all(np.all(np.isfinite(q)) for q in qs):
        raise ValueError("every waypoint must have the same number of finite joint values")
    v, a = _check_limits(velocity, acceleration, n)
    if len(qs) == 1:
        return Trajectory([_segment(qs[0], qs[0], 0.0, v, a)])
    return Trajectory([_segment(q0, q1, 0.0, v, a) for q0, q1 in pairwise(qs)])


__all__ = ["Trajectory", "TrajectoryPoint", "straight_line_duration", "time_parameterise"]
