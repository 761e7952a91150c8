"""The lifter: four posts braced at the foot, a Top Gripper pin at each corner of the top level, and
a carriage on each post carrying an Active Gripper latch."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from tlt_sim.model import names
from tlt_sim.model.generate.document import Document, sub
from tlt_sim.model.generate.layout import TowerLayout


def add_lifter(doc: Document, layout: TowerLayout, edu: dict[str, Any]) -> ET.Element:
    """The ``lifter`` frame (posts, beams, Top Grippers) and the four carriages; returns the frame,
    which the camera mounts hang on.

    Reads ``lifter``, ``top_grippers``, ``active_grippers`` and ``parts.corner_size`` of ``edu``.
    """
    lf, ag, tg = edu["lifter"], edu["active_grippers"], edu["top_grippers"]
    r, height = lf["post_radius"], lf["post_height"]
    frame = sub(doc.world, "body", name="lifter")
    for i, p in enumerate(layout.post_xy):
        sub(
            frame,
            "geom",
            name=f"lifter/post_{i}",
            class_="env",
            type="cylinder",
            size=(r, height / 2),
            pos=(p[0], p[1], height / 2),
        )
        # Bracing only at the foot: a ring at the top would stand in the arms' way.
        q = layout.post_xy[(i + 1) % 4]
        sub(
            frame,
            "geom",
            name=f"lifter/beam_{i}",
            class_="env",
            type="capsule",
            size=(r * 0.7,),
            fromto=(p[0], p[1], 0.05, q[0], q[1], 0.05),
        )
        _top_gripper(doc, layout, frame, i, tg, edu["parts"]["corner_size"] / 2, r)
    for i, p in enumerate(layout.post_xy):
        _carriage(doc, layout, i, p, lf, ag)
    return frame


def _top_gripper(
    doc: Document,
    layout: TowerLayout,
    frame: ET.Element,
    i: int,
    tg: dict[str, Any],
    half: float,
    post_radius: float,
) -> None:
    c, o = layout.corner_xy[i], layout.outward[i]
    tip_engaged = c + o * half
    base = tip_engaged + o * tg["stroke"]  # pin tip when retracted (joint at zero)
    bracket_end = layout.post_xy[i] - o * post_radius
    z = layout.top_level
    sub(
        frame,
        "geom",
        name=f"top_gripper_{i}/bracket",
        class_="mech",
        type="box",
        size=(0.03, 0.03, 0.02),
        pos=(
            (base[0] + bracket_end[0]) / 2 + o[0] * 0.02,
            (base[1] + bracket_end[1]) / 2 + o[1] * 0.02,
            z + 0.05,
        ),
    )
    pin = sub(frame, "body", name=names.top_gripper(i), pos=(base[0], base[1], z))
    joint = names.top_gripper(i)
    sub(
        pin,
        "joint",
        name=joint,
        type="slide",
        axis=(-o[0], -o[1], 0.0),
        range=(0.0, tg["stroke"]),
        armature=0.5,
        damping=5.0,
    )
    sub(
        pin,
        "geom",
        class_="mech",
        type="capsule",
        size=(0.008,),
        fromto=(0, 0, 0, o[0] * 0.12, o[1] * 0.12, 0.0),
        mass=0.1,
        rgba=(0.8, 0.75, 0.2, 1),
    )
    sub(pin, "site", name=f"{joint}/tip", size=(0.006,))
    doc.actuator(joint, 5000.0, 200.0, 120.0, (0.0, tg["stroke"]))


def _carriage(
    doc: Document, layout: TowerLayout, i: int, p: np.ndarray, lf: dict[str, Any], ag: dict[str, Any]
) -> None:
    c, o = layout.corner_xy[i], layout.outward[i]
    z0 = layout.build_level - lf["build_position"]
    body = sub(doc.world, "body", name=f"lifter_carriage_{i}", pos=(p[0], p[1], z0))
    joint = names.lifter_joint(i)
    sub(
        body,
        "joint",
        name=joint,
        type="slide",
        axis=(0, 0, 1),
        range=lf["travel"],
        armature=5.0,
        damping=200.0,
    )
    sub(
        body,
        "geom",
        class_="mech",
        type="box",
        size=(0.06, 0.06, 0.05),
        mass=lf["carriage_mass"],
        rgba=(0.2, 0.2, 0.22, 1),
    )
    f = ag["finger_length"]
    hinge = c + o * f
    rel = hinge - p
    sub(
        body,
        "geom",
        class_="mech",
        type="capsule",
        size=(0.015,),
        fromto=(0, 0, 0, rel[0], rel[1], 0),
        mass=0.2,
    )
    doc.actuator(joint, lf["kp"], 2.0 * math.sqrt(lf["kp"] * 60.0), 8000.0, lf["travel"])
    latch = sub(body, "body", name=names.active_gripper(i), pos=(rel[0], rel[1], 0.0))
    ajoint = names.active_gripper(i)
    sub(
        latch,
        "joint",
        name=ajoint,
        type="hinge",
        axis=(0, 0, 1),
        range=ag["range"],
        armature=0.05,
        damping=0.5,
    )
    inward = -o
    v0 = np.array([inward[1], -inward[0]])  # rotated +90 deg about z this points inward
    sub(
        latch,
        "geom",
        class_="mech",
        type="capsule",
        size=(0.012,),
        fromto=(0, 0, 0, v0[0] * f, v0[1] * f, 0),
        mass=0.15,
        rgba=(0.1, 0.4, 0.8, 1),
    )
    sub(latch, "site", name=f"{ajoint}/tip", pos=(v0[0] * f, v0[1] * f, 0.0), size=(0.006,))
    doc.actuator(ajoint, 40.0, 2.0, 8.4, ag["range"])


__all__ = ["add_lifter"]
