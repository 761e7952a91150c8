"""The equality constraints assembly is made of, all inactive: the scene turns them on
(see :mod:`tlt_sim.model.assembly`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from tlt_sim.model import names
from tlt_sim.model.generate.document import Document, sub
from tlt_sim.model.generate.info import ModelInfo


def add_equalities(
    doc: Document,
    physics: dict[str, Any],
    bay_width: float,
    info: ModelInfo,
) -> None:
    """For the cross frames, struts and parts of ``info``: per cross frame and corner, a connect to
    each holder (Top Grippers on the lifter frame, the Active Gripper's carriage, the foundation); a
    rivet weld per strut and cross frame; a grasp weld per arm and part. Solrefs are ``physics``'
    (``edu.physics``)."""
    w = bay_width
    holders = [("top", "lifter"), ("active", None), ("foundation", "foundation")]
    for cf in info.cross_frames:
        for i in range(4):
            anchor = np.array([names.CORNER_XY[i][0] * w, names.CORNER_XY[i][1] * w, 0.0])
            for kind, other in holders:
                body2 = other or f"lifter_carriage_{i}"
                sub(
                    doc.equality,
                    "connect",
                    name=f"{kind}/{i}/{cf}",
                    body1=cf,
                    body2=body2,
                    anchor=anchor,
                    active="false",
                    solref=physics["hold_solref"],
                )
    for strut in info.struts:
        for cf in info.cross_frames:
            sub(
                doc.equality,
                "weld",
                name=f"rivet/{strut}/{cf}",
                body1=strut,
                body2=cf,
                active="false",
                solref=physics["rivet_solref"],
            )
    for arm in names.ARMS:
        for part in info.parts.values():
            sub(
                doc.equality,
                "weld",
                name=f"grasp/{arm}/{part.body}",
                body1=names.ee_body(arm),
                body2=part.body,
                active="false",
                solref=physics["grasp_solref"],
            )


__all__ = ["add_equalities"]
