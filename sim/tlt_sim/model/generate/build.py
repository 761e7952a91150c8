"""The EDU's MJCF, composed of one builder per assembly, in the order the document lists them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tlt_common.mission.schema import Mission
from tlt_sim.model import names
from tlt_sim.model.generate.arm import add_arm
from tlt_sim.model.generate.camera_mounts import add_camera_mounts
from tlt_sim.model.generate.dispensers import add_dispensers
from tlt_sim.model.generate.document import Document
from tlt_sim.model.generate.equalities import add_equalities
from tlt_sim.model.generate.foundation import add_foundation
from tlt_sim.model.generate.info import ModelInfo
from tlt_sim.model.generate.layout import TowerLayout
from tlt_sim.model.generate.lifter import add_lifter
from tlt_sim.model.generate.payload import add_payload
from tlt_sim.model.scenario import NOMINAL, Scenario


def build_model(
    edu: dict[str, Any], mission: Mission, out_dir: str | Path, scenario: Scenario = NOMINAL
) -> ModelInfo:
    """Write ``edu.xml`` and the tag textures into ``out_dir``; return what was built."""
    out = Path(out_dir)
    layout = TowerLayout.of(edu, mission)
    info = ModelInfo(out / "edu.xml", out, edu, mission, scenario, top_level=layout.top_level)
    info.tower_origin = layout.tower_origin
    info.post_xy = layout.post_xy
    doc = Document(f"tlt_edu_{mission.name}", edu["physics"])
    add_foundation(doc, layout, edu["site"]["foundation_top"])
    frame = add_lifter(doc, layout, edu)
    add_camera_mounts(doc, layout, frame, edu["camera_mounts"], edu["cameras"]["zed_fovy_deg"])
    info.cross_frames.append(add_payload(doc, layout, edu["payload"], edu["parts"]))
    for arm in names.ARMS:
        add_arm(doc, arm, edu)
    dispensed = add_dispensers(doc, edu, mission, scenario, layout.base_origin, out)
    info.dispenser_tags.update(dispensed.tags)
    info.parts.update(dispensed.parts)
    info.cross_frames.extend(dispensed.cross_frames)
    add_equalities(doc, edu["physics"], layout.bay_width, info)
    doc.write(info.xml_path)
    return info


__all__ = ["build_model"]
