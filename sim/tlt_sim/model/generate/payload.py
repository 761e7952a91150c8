"""The payload: the tower's top cross frame, free, with the payload box on it."""

from __future__ import annotations

from typing import Any

from tlt_sim.model.generate.document import Document, sub
from tlt_sim.model.generate.layout import TowerLayout
from tlt_sim.model.generate.parts import cross_frame_geoms


def add_payload(doc: Document, layout: TowerLayout, payload: dict[str, Any], parts: dict[str, Any]) -> str:
    """The ``payload`` body at the tower origin; returns its name (a cross frame grippers and
    rivets hold). ``payload`` and ``parts`` are those sections of the EDU description."""
    body = sub(doc.world, "body", name="payload", pos=layout.tower_origin)
    sub(body, "freejoint", name="payload")
    cross_frame_geoms(body, "payload", parts, layout.bay_width)
    sx, sy, sz = payload["size"]
    w = layout.bay_width
    sub(
        body,
        "geom",
        name="payload/box",
        class_="mech",
        type="box",
        size=(sx / 2, sy / 2, sz / 2),
        pos=(w / 2, w / 2, 0.04 + sz / 2),
        mass=payload["mass"],
        rgba=(0.85, 0.82, 0.7, 1),
    )
    return "payload"


__all__ = ["add_payload"]
