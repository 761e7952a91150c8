"""Time parameterisation of piecewise-linear joint paths under the UR10e's velocity and
acceleration limits.

Reads a list of waypoints (rad) and per-joint limits; writes a trajectory as a list of
:class:`TrajectoryPoint` (time from start, positions, velocities, accelerations), the shape of a
``trajectory_msgs/JointTrajectory``.

Each segment of the path is followed exactly, in a straight joint-space line, with all joints
synchronised: the path parameter s in [0, 1] follows a trapezoidal (or triangular) velocity
profile whose peak velocity and acceleration are the largest any joint allows for that segment,
so the limiting joint runs at its limit. The arm stops at every interior waypoint, because a
straight-line path cannot turn a corner at speed without leaving the checked path. For one
segment this profile is the time-optimal motion along the joint-space straight line, which is
what :func:`straight_line_duration` returns.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np


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


class Trajectory:
    """A time-parameterised path: sample it anywhere, or list points at a fixed period."""

    def __init__(self, segments: list[_Segment]) -> None:
        self._segments = segments
        self.duration = sum(s.duration for s in segments)
        self._starts = np.cumsum([0.0] + [s.duration for s in segments])

    def sample(self, t: float) -> TrajectoryPoint:
        t = min(max(t, 0.0), self.duration)
        k = int(np.searchsorted(self._starts, t, side="right") - 1)
        k = min(max(k, 0), len(self._segments) - 1)
        q, qd, qdd = self._segments[k].sample(t - self._starts[k])
        return TrajectoryPoint(t, q, qd, qdd)

    def points(self, period: float) -> list[TrajectoryPoint]:
        """Samples every ``period`` seconds plus every segment boundary and the end, in time order."""
        if period <= 0:
            raise ValueError("sample period must be positive")
        times = set(np.arange(0.0, self.duration, period).round(9).tolist())
        times.update(float(t) for t in self._starts)
        return [self.sample(t) for t in sorted(times)]

    def waypoints(self) -> list[TrajectoryPoint]:
        """One point per path waypoint (at rest), as a JointTrajectory with stops would list them."""
        return [self.sample(float(t)) for t in self._starts]


def time_parameterise(
    path: Sequence[Sequence[float]], velocity: Sequence[float], acceleration: Sequence[float]
) -> Trajectory:
    """Time-parameterise ``path`` (at least one waypoint), starting and ending at rest."""
    qs = [np.asarray(q, dtype=float) for q in path]
    if not qs:
        raise ValueError("an empty path cannot be time-parameterised")
    n = qs[0].shape[0]
    if any(q.shape != (n,) for q in qs) or not all(np.all(np.isfinite(q)) for q in qs):
        raise ValueError("every waypoint must have the same number of finite joint values")
    v, a = _check_limits(velocity, acceleration, n)
    segments = []
    t = 0.0
    if len(qs) == 1:
        return Trajectory([_segment(qs[0], qs[0], 0.0, v, a)])
    for q0, q1 in pairwise(qs):
        seg = _segment(q0, q1, t, v, a)
        segments.append(seg)
        t += seg.duration
    return Trajectory(segments)


__all__ = ["Trajectory", "TrajectoryPoint", "straight_line_duration", "time_parameterise"]
