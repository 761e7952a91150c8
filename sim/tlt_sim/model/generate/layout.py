"""Where the tower stands and the machine around it: the bay's corners, the lifter posts, the levels.

World frame: z up, floor at z = 0, the mission's "base" frame at ``site.base_origin``. The tower
frame (corner x0_y0 of the payload's cross frame, mission ``bay0``) starts at
``(0, 0, build_level + bay_height)``; bay n's bottom cross frame is at ``-n * bay_height`` in it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from tlt_common.mission.schema import Mission
from tlt_sim.model import names


@dataclass(frozen=True)
class TowerLayout:
    """The tower's geometry in the world, shared by every builder.

    ``corner_xy``: the bay's corners (x, y) in corner order (:data:`names.CORNER_XY`).
    ``outward``: from each corner to its post's side, along a side of the square, turning around
    it (a pinwheel), so no post stands on the diagonal where the arms reach in to the corners.
    ``diagonal``: from the bay's centre out through each corner (unit vectors).
    ``post_xy``: the lifter posts, ``lifter.post_offset`` out along the diagonal from each corner.
    """

    bay_width: float
    bay_height: float
    build_level: float
    top_level: float  # the payload's cross frame: build_level + bay_height
    base_origin: np.ndarray
    corner_xy: list[np.ndarray]
    outward: list[np.ndarray]
    diagonal: list[np.ndarray]
    post_xy: list[np.ndarray]

    @classmethod
    def of(cls, edu: dict[str, Any], mission: Mission) -> TowerLayout:
        w = mission.bay_width
        site = edu["site"]
        corner_xy = [np.array([i * w, j * w]) for i, j in names.CORNER_XY]
        centre = np.array([w / 2, w / 2])
        diagonal = [(c - centre) / np.linalg.norm(c - centre) for c in corner_xy]
        off = edu["lifter"]["post_offset"]
        return cls(
            bay_width=w,
            bay_height=mission.bay_height,
            build_level=site["build_level"],
            top_level=site["build_level"] + mission.bay_height,
            base_origin=np.asarray(site["base_origin"], dtype=float),
            corner_xy=corner_xy,
            outward=[np.array(v, dtype=float) for v in ((0, -1), (1, 0), (0, 1), (-1, 0))],
            diagonal=diagonal,
            post_xy=[c + off * d for c, d in zip(corner_xy, diagonal, strict=True)],
        )

    @property
    def tower_origin(self) -> np.ndarray:
        """The tower frame's origin in the world (a new array each time)."""
        return np.array([0.0, 0.0, self.top_level])


__all__ = ["TowerLayout"]
