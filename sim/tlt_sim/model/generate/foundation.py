"""The foundation: a pad under each corner of the bay, up to ``site.foundation_top``."""

from __future__ import annotations

from tlt_sim.model.generate.document import PART_BIT, Document, sub
from tlt_sim.model.generate.layout import TowerLayout


def add_foundation(doc: Document, layout: TowerLayout, foundation_top: float) -> None:
    """The ``foundation`` body, its pads at the bay's corners."""
    body = sub(doc.world, "body", name="foundation")
    for i, c in enumerate(layout.corner_xy):
        sub(
            body,
            "geom",
            name=f"foundation/pad_{i}",
            class_="env",
            # Falling parts land on the pads as on the floor: a cross frame the ARS lets go of
            # at the build level rests on them until the Active Grippers latch it (as on the EDU).
            # The arms do not touch them: a rivet gun at a corner joint reaches just above a
            # pad, and the ARS planning scene does not model the pads either.
            conaffinity=PART_BIT,
            type="box",
            size=(0.035, 0.035, foundation_top / 2),
            pos=(c[0], c[1], foundation_top / 2),
            rgba=(0.35, 0.3, 0.25, 1),
        )


__all__ = ["add_foundation"]
