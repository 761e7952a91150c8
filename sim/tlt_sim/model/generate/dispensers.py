"""The dispensers: a rack of parts (or a rivet feeder) per mission dispenser, its AprilTag on a post
beside it, and the parts in its slots."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tlt_common.geometry.transforms import rotation_to_mujoco_quat, rpy_matrix
from tlt_common.mission.schema import Mission
from tlt_sim.model.apriltag import write_tag_png
from tlt_sim.model.generate.document import Document, sub
from tlt_sim.model.generate.end_effector import GUN_HALF
from tlt_sim.model.generate.info import PartInfo
from tlt_sim.model.generate.parts import add_part
from tlt_sim.model.scenario import Scenario

# Rack uprights: half width of their square section, and the gap kept between a cross-frame
# upright and a rivet gun over the corner it stands by (the fine approach's error budget).
UPRIGHT_HALF, UPRIGHT_GUN_GAP = 0.015, 0.03


@dataclass
class Dispensed:
    """What :func:`add_dispensers` made: the tag id of each dispenser, the parts (in dispenser and
    slot order) and the cross frames among them."""

    tags: dict[str, int] = field(default_factory=dict)
    parts: dict[str, PartInfo] = field(default_factory=dict)
    cross_frames: list[str] = field(default_factory=list)


def rack_uprights(
    cross_frame: bool, extent: float, bay_width: float, edu: dict[str, Any]
) -> list[tuple[int, int, float, float]]:
    """The four uprights of a part rack, ``(sx, sy, x, y)`` in the dispenser's frame.

    ``extent`` is the parts' length along the rack's x. A grasp puts the EE's rivet guns over both
    ends of the grasped bar, outboard of it: strut racks keep their uprights beyond the strut ends,
    and cross-frame racks (whose frames may be taken by any side) stand theirs diagonally out from
    each corner, a gun's half length plus a gap beyond it both ways, so that no side's guns meet
    them (an upright by a corner stopped the EE short of every frame below the top one).
    """
    if cross_frame:
        out = GUN_HALF[0] + UPRIGHT_HALF + UPRIGHT_GUN_GAP
        half_x, half_y = extent / 2 + out, bay_width / 2 + out
    else:
        half_x = extent / 2 + edu["end_effector"]["rivet_gun_offset"] * 0.9
        # Close to the strut's axis: beyond the strut ends they need no width, and wider they
        # stood where a rivet gun picks a rivet from the feeder beside the rack.
        half_y = 0.02
    return [(sx, sy, sx * half_x, sy * half_y) for sx in (-1, 1) for sy in (-1, 1)]


def add_dispensers(
    doc: Document,
    edu: dict[str, Any],
    mission: Mission,
    scenario: Scenario,
    base_origin: np.ndarray,
    out_dir: Path,
) -> Dispensed:
    """Every dispenser of ``mission`` (tag ids in mission order), its tag's PNG texture written
    into ``out_dir``, and its parts (none in a dispenser the scenario empties; defects as the
    scenario gives them). Reads ``dispensers``, ``parts`` and ``end_effector`` of ``edu``."""
    d_cfg = edu["dispensers"]
    made = Dispensed()
    for tag_id, (name, disp) in enumerate(mission.dispensers.items()):
        made.tags[name] = tag_id
        rot = rpy_matrix(disp.rpy)
        pos = base_origin + np.asarray(disp.position, dtype=float)
        body = sub(doc.world, "body", name=f"dispenser/{name}", pos=pos, quat=rotation_to_mujoco_quat(rot))
        count = 0 if name in scenario.empty else disp.count
        extent = _extent(mission, disp.part_kind)
        top = d_cfg["first_slot_height"] + max(count - 1, 0) * d_cfg["slot_pitch"]
        if disp.part_kind == "rivet":
            top = _rivet_feeder(body, name, pos, count, d_cfg["rivet_pickup_height"])
        else:
            _rack(body, name, extent, top, mission.bay_width, edu)
        _tag(doc, body, name, tag_id, extent, top, d_cfg["tag_size"], out_dir)
        if disp.part_kind != "rivet":
            for index in range(count):
                z = d_cfg["first_slot_height"] + (count - 1 - index) * d_cfg["slot_pitch"]
                pname = f"{name}/{index}"
                defect = scenario.defects.get(pname)
                part = add_part(
                    doc, mission, edu["parts"], name, disp.part_kind, index, (pos, rot, z), defect
                )
                made.parts[pname] = part
                if part.kind == "cross_frame":
                    made.cross_frames.append(part.body)
    return made


def _extent(mission: Mission, kind: str) -> float:
    if kind == "cross_frame":
        return mission.bay_width
    if kind == "rivet":
        return 0.08
    return mission.strut_lengths[kind]


def _rivet_feeder(body: ET.Element, name: str, pos: np.ndarray, count: int, lift: float) -> float:
    """A feeder column on the dispenser's frame; rivets wait in a tray at its top. Returns the
    tray's height."""
    sub(
        body,
        "geom",
        name=f"dispenser/{name}/column",
        class_="env",
        type="cylinder",
        size=(0.02, (pos[2] + lift) / 2),
        pos=(0, 0, (lift - pos[2]) / 2 - 0.03),
    )
    sub(
        body,
        "geom",
        name=f"dispenser/{name}/box",
        class_="env",
        type="box",
        size=(0.04, 0.04, 0.03),
        pos=(0, 0, lift),
    )
    for k in range(min(count, 9)):
        sub(
            body,
            "geom",
            name=f"dispenser/{name}/rivet_{k}",
            class_="deco",
            type="cylinder",
            size=(0.006, 0.012),
            pos=(-0.025 + 0.025 * (k % 3), -0.025 + 0.025 * (k // 3), lift + 0.042),
            material="rivet",
        )
    sub(body, "site", name=f"dispenser/{name}/pickup", pos=(0, 0, lift + 0.05), size=(0.01,))
    return lift


def _rack(
    body: ET.Element, name: str, extent: float, top: float, bay_width: float, edu: dict[str, Any]
) -> None:
    height = top + 0.05
    uprights = rack_uprights(name.startswith("cross"), extent, bay_width, edu)
    for sx, sy, x, y in uprights:
        sub(
            body,
            "geom",
            name=f"dispenser/{name}/upright_{sx}_{sy}".replace("-", "m"),
            class_="env",
            type="box",
            size=(UPRIGHT_HALF, UPRIGHT_HALF, height / 2),
            pos=(x, y, height / 2),
        )
    x, y = abs(uprights[0][2]), abs(uprights[0][3])
    sub(
        body,
        "geom",
        name=f"dispenser/{name}/base",
        class_="env",
        type="box",
        size=(x + 0.02, y + 0.02, 0.01),
        pos=(0, 0, 0.01),
    )


def _tag(
    doc: Document,
    body: ET.Element,
    name: str,
    tag_id: int,
    extent: float,
    top: float,
    size: float,
    out_dir: Path,
) -> None:
    png = write_tag_png(tag_id, out_dir / f"tag36h11_{tag_id}.png")
    sub(doc.asset, "texture", name=f"tag_{tag_id}", type="2d", file=str(png.resolve()))
    sub(
        doc.asset,
        "material",
        name=f"tag_{tag_id}",
        texture=f"tag_{tag_id}",
        specular=0.0,
        rgba=(1, 1, 1, 1),
    )
    x = -(extent / 2 + 0.15 + size / 2)
    z = top + 0.06
    sub(
        body,
        "geom",
        name=f"dispenser/{name}/tag_post",
        class_="env",
        type="box",
        size=(0.015, 0.015, z / 2),
        pos=(x, 0, z / 2),
    )
    sub(
        body,
        "geom",
        name=f"dispenser/{name}/tag",
        class_="deco",
        type="box",
        size=(size / 2, size / 2, 0.002),
        pos=(x, 0, z + 0.002),
        material=f"tag_{tag_id}",
    )
    sub(body, "site", name=f"dispenser/{name}/tag", pos=(x, 0, z + 0.004), size=(0.005,))


__all__ = ["Dispensed", "add_dispensers", "rack_uprights"]
