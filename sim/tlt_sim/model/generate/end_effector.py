"""The end effector on an arm's flange: a hub and bar carrying two grippers (b slides on the width
joint), each with a Dynamixel jaw, a rivet gun outboard of the grasp line and a D405 camera."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from tlt_common.geometry.transforms import rot_x
from tlt_sim.model import names
from tlt_sim.model.generate.document import Document, sub
from tlt_sim.model.geometry import look_at_xyaxes

# Rivet gun body of the end effector (half extents, m) and how far it sits outboard of the grasp
# line, across the bar: a gun hangs over each end of whatever side of a part is grasped.
GUN_HALF, GUN_OUTBOARD = (0.025, 0.025, 0.04), 0.06


def add_end_effector(
    doc: Document,
    arm: str,
    ee: ET.Element,
    e: dict[str, Any],
    tube_radius: float,
    cameras: dict[str, Any],
) -> None:
    """The end effector of ``arm`` in its flange body ``ee``; ``e`` is ``edu.end_effector``,
    ``tube_radius`` the parts' (where the jaws meet a tube) and ``cameras`` ``edu.cameras``."""
    s, depth = e["grip_spacing"], e["grasp_depth"]
    sub(
        ee,
        "geom",
        name=f"{arm}/ee/hub",
        class_="arm",
        type="cylinder",
        size=(0.045, 0.02),
        pos=(0, 0, 0.02),
        mass=0.4,
    )
    sub(
        ee,
        "geom",
        name=f"{arm}/ee/bar",
        class_="arm",
        type="box",
        size=(e["bar_length"] / 2, 0.03, 0.02),
        pos=(0, 0, 0.06),
        mass=1.5,
        rgba=(0.3, 0.3, 0.32, 1),
    )
    sub(ee, "site", name=f"{arm}/ee/grasp_centre", pos=(0, 0, depth), size=(0.006,))
    grip_a = sub(ee, "body", name=f"{arm}/gripper_a", pos=(-s / 2, 0, 0), gravcomp=1)
    _gripper(doc, arm, "a", grip_a, -1.0, e, tube_radius, cameras)
    grip_b = sub(ee, "body", name=f"{arm}/gripper_b", pos=(s / 2, 0, 0), gravcomp=1)
    wjoint = names.width_joint(arm)
    sub(
        grip_b,
        "joint",
        name=wjoint,
        type="slide",
        axis=(1, 0, 0),
        range=(0.0, e["width_travel"]),
        armature=1.0,
        damping=20.0,
    )
    doc.actuator(wjoint, 8000.0, 300.0, 300.0, (0.0, e["width_travel"]))
    _gripper(doc, arm, "b", grip_b, 1.0, e, tube_radius, cameras)
    sub(ee, "site", name=f"{arm}/limit_switch", pos=(s / 2, 0.035, 0.06), size=(0.006,))


def _gripper(
    doc: Document,
    arm: str,
    side: str,
    body: ET.Element,
    sign: float,
    e: dict[str, Any],
    tube_radius: float,
    cameras: dict[str, Any],
) -> None:
    depth, g = e["grasp_depth"], e["rivet_gun_offset"]
    sub(
        body,
        "geom",
        name=f"{arm}/gripper_{side}/body",
        class_="arm",
        type="box",
        size=(0.025, 0.03, (depth - 0.08) / 2),
        pos=(0, 0, 0.08 + (depth - 0.08) / 2 - 0.02),
        mass=0.6,
        rgba=(0.2, 0.2, 0.22, 1),
    )
    sub(body, "site", name=f"{arm}/grip_{side}", pos=(0, 0, depth), size=(0.006,))
    sub(
        body,
        "geom",
        name=f"{arm}/gripper_{side}/finger",
        class_="arm",
        type="box",
        size=(0.012, 0.006, 0.03),
        pos=(0, 0.032, depth),
        mass=0.05,
    )
    # The jaw is a finger on a Dynamixel hinge along the grasp line (as ee_x.yaml: rad); at
    # jaw_contact its tip meets a tube lying on the line.
    hinge = np.array([0.0, -0.045, depth - 0.045])
    tip = np.array([0.0, -tube_radius, depth])
    reach = float(np.linalg.norm(tip - hinge))
    finger = rot_x(-e["jaw_contact"]) @ ((tip - hinge) / reach)  # its direction at angle 0
    jaw = sub(body, "body", name=f"{arm}/jaw_{side}", pos=hinge, gravcomp=1)
    joint = names.grasp_joint(arm, side)
    sub(
        jaw,
        "joint",
        name=joint,
        type="hinge",
        axis=(1, 0, 0),
        range=e["jaw_range"],
        armature=0.02,
        damping=0.1,
    )
    sub(
        jaw,
        "geom",
        class_="arm",
        type="capsule",
        size=(0.007,),
        fromto=(0, 0, 0, *(finger * reach)),
        mass=0.05,
        rgba=(0.8, 0.2, 0.2, 1),
    )
    doc.actuator(joint, 20.0, 0.5, 8.4, tuple(e["jaw_range"]))
    gx = sign * g
    sub(
        body,
        "geom",
        name=f"{arm}/rivet_gun_{side}/body",
        class_="arm",
        type="box",
        size=GUN_HALF,
        pos=(gx, -GUN_OUTBOARD, depth - 0.05),
        mass=0.8,
        rgba=(0.9, 0.75, 0.1, 1),
    )
    sub(
        body,
        "geom",
        name=f"{arm}/rivet_gun_{side}/bracket",
        class_="arm",
        type="box",
        size=(abs(gx) / 2 + 0.02, 0.01, 0.01),
        pos=(gx / 2, -GUN_OUTBOARD, depth - 0.1),
        mass=0.1,
    )
    sub(body, "site", name=names.rivet_gun_site(arm, side), pos=(gx, 0, depth), size=(0.008,))
    # The rivet in the gun's muzzle: drawn (and seen by the D405) only while the gun is loaded;
    # the assembly physics shows and hides it (alpha), it touches nothing.
    sub(
        body,
        "geom",
        name=names.loaded_rivet_geom(arm, side),
        class_="deco",
        type="cylinder",
        size=(0.006, 0.012),
        pos=(gx, 0, depth),
        rgba=(0.9, 0.1, 0.1, 0.0),
    )
    _d405(body, arm, side, sign, gx, depth, cameras)


def _d405(
    body: ET.Element, arm: str, side: str, sign: float, gx: float, depth: float, cameras: dict[str, Any]
) -> None:
    """The D405 beside gripper ``side``, tilted by ``cameras.d405_tilt_deg`` to look at the gun's
    muzzle line."""
    cam_pos = np.array([sign * 0.06, 0.075, 0.07])
    tilt = math.radians(cameras["d405_tilt_deg"])
    target = np.array([gx - sign * depth * math.tan(tilt), 0.0, depth])
    look = target - cam_pos
    sub(
        body,
        "geom",
        name=f"{arm}/d405_{side}/housing",
        class_="arm",
        type="box",
        size=(0.021, 0.021, 0.0115),
        pos=cam_pos - [0, 0, 0.015],
        mass=0.06,
        rgba=(0.15, 0.15, 0.15, 1),
    )
    sub(
        body,
        "camera",
        name=names.d405_camera(arm, side),
        pos=cam_pos,
        xyaxes=look_at_xyaxes(look, up=(sign, 0.0, 0.0)),
        fovy=cameras["d405_fovy_deg"],
    )


__all__ = ["GUN_HALF", "GUN_OUTBOARD", "add_end_effector"]
