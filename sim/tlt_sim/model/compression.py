"""The bay compression test of the twin: how far a built bay gives under the lifter's push.

The lifter's push reaches the bottom cross frame through the Active Grippers; here it is a force
on that frame while the latches' constraints are lifted, so that the bay's struts and rivets carry
all of it. The result is the frame's displacement along the tower axis, and so the bay's stiffness,
and how far each rivet joint slips under the load (the twin's truth of each joint's share: a rivet
that did not seat or a loose joint slips measurably more than a good one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from tlt_sim.model import names
from tlt_sim.model.assembly import Assembly


@dataclass
class CompressionResult:
    force_n: float
    displacement_m: float  # bottom cross frame towards the top one, under the force
    top: str
    bottom: str
    slips_m: dict[str, float] = field(default_factory=dict)  # rivet equality -> slip under the load

    @property
    def stiffness_n_per_m(self) -> float:
        return self.force_n / self.displacement_m if self.displacement_m > 0 else float("inf")


def compression_test(
    assembly: Assembly, step: Callable[[float], None], force_n: float, settle_s: float
) -> CompressionResult:
    """Push the cross frame the Active Grippers hold towards the one the Top Grippers hold, with
    ``force_n``, the simulation advanced by ``step(seconds)``. Returns the displacement along the
    tower axis after ``settle_s`` of simulated time. Fails (ValueError) unless both grippers hold
    a frame, each its own.
    """
    data = assembly.d
    tops = {p for p in assembly.pins if p}
    bottoms = {p for p in assembly.latches if p}
    if len(tops) != 1 or len(bottoms) != 1 or tops == bottoms:
        raise ValueError(
            f"compression test needs the Top Grippers on one cross frame and the Active Grippers on"
            f" another (top: {sorted(tops)}, active: {sorted(bottoms)})"
        )
    top, bottom = tops.pop(), bottoms.pop()
    b = assembly.m.body(bottom).id
    axis = assembly.body_pose(top)[1][:, 2]
    latched = [(i, f"active/{i}/{bottom}") for i, h in enumerate(assembly.latches) if h == bottom]
    for _, name in latched:
        assembly.switch_off(name)
    step(settle_s)
    before = data.xpos[b].copy() - assembly.body_pose(top)[0]
    data.xfrc_applied[b, :3] = axis * force_n
    try:
        step(settle_s)
        after = data.xpos[b].copy() - assembly.body_pose(top)[0]
        slips = {name: assembly.slip(name) for name in assembly.active("rivet/")}
    finally:
        data.xfrc_applied[b, :] = 0.0
    step(settle_s)
    for i, name in latched:
        assembly.connect(name, assembly.site_pos(names.corner_site(bottom, i)))
    return CompressionResult(force_n, float((after - before) @ axis), top, bottom, slips)


__all__ = ["CompressionResult", "compression_test"]
