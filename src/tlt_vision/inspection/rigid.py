"""The best rigid motion of a set of expected points onto observed ones, and what is left over:
the camera's pose drops out of a check made on the residuals."""

from __future__ import annotations

import numpy as np


def rigid_fit(expected: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``R``, ``t`` with ``R e_i + t ~ o_i`` (least squares). For two points the smallest rotation
    that turns one's direction into the other's: the roll about their line is not observed."""
    ce, co = expected.mean(0), observed.mean(0)
    if len(expected) == 2:
        r = rotation_between(expected[1] - expected[0], observed[1] - observed[0])
    else:
        h = (expected - ce).T @ (observed - co)
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
        r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, co - r @ ce


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction ``a`` onto direction ``b``."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1.0 + 1e-12:  # opposite: half a turn about any axis normal to a
        n = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        n /= np.linalg.norm(n)
        return 2.0 * np.outer(n, n) - np.eye(3)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def rigid_residuals(expected: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Residual distances after the best rigid fit of ``expected`` (n, 3) onto ``observed``."""
    r, t = rigid_fit(expected, observed)
    return np.linalg.norm(expected @ r.T + t - observed, axis=1)
