"""The loose parts: a cross frame (four sides and four corner joints) or a strut (a tube with an
end fitting and its rivet at each end, or the defect its scenario gives it), each a free body."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from tlt_common.geometry.transforms import rot_x, rot_y, rotation_to_mujoco_quat
from tlt_common.mission.schema import Mission
from tlt_sim.model import names
from tlt_sim.model.generate.document import HIDDEN_GROUP, Document, sub
from tlt_sim.model.generate.info import PartInfo
from tlt_sim.model.scenario import Defect


def cross_frame_geoms(
    body: ET.Element, prefix: str, parts: dict[str, Any], bay_width: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The sides, corner joints and corner sites of a cross frame in ``body`` (corner 0 at its
    origin); returns its grasps (middle of each side, along it). ``parts`` is ``edu.parts``."""
    w, half, r = bay_width, parts["corner_size"] / 2, parts["tube_radius"] * 1.2
    mass = parts["cross_frame_mass"]
    corners = [np.array([x * w, y * w, 0.0]) for x, y in names.CORNER_XY]
    grasps = []
    side_mass = mass * 0.8 / 4
    for i, c in enumerate(corners):
        d = corners[(i + 1) % 4] - c
        u = d / np.linalg.norm(d)
        a, b = c + u * half, corners[(i + 1) % 4] - u * half
        sub(
            body,
            "geom",
            name=f"{prefix}/side_{i}",
            class_="part",
            type="capsule",
            size=(r,),
            fromto=(*a, *b),
            material="cross_frame",
            mass=side_mass,
        )
        grasps.append((c + d / 2, u))
    for i, c in enumerate(corners):
        sub(
            body,
            "geom",
            name=f"{prefix}/corner_{i}",
            class_="part",
            type="box",
            size=(half,) * 3,
            pos=c,
            material="corner_joint",
            mass=mass * 0.2 / 4,
        )
        sub(body, "site", name=names.corner_site(prefix, i), pos=c, size=(0.005,))
    return grasps


def strut_geoms(
    body: ET.Element, prefix: str, parts: dict[str, Any], length: float, defect: Defect | None
) -> dict[str, np.ndarray]:
    """The tube, end fittings and (hidden) rivet heads and shanks of a strut along ``body``'s z, end a at its
    origin; returns its ends. A ``bent_tube`` defect kinks the tube at mid-length, a
    ``missing_end_fitting`` one leaves that end's fitting out."""
    p = parts
    half, fl, mass = p["corner_size"] / 2, p["fitting_length"], p["strut_mass"]
    ends = {"a": np.zeros(3), "b": np.array([0.0, 0.0, length])}
    tube_a, tube_b = np.array([0, 0, half + fl]), np.array([0, 0, length - half - fl])
    tube_mass = mass * 0.7

    def tube(name: str, a: np.ndarray, b: np.ndarray, weight: float) -> None:
        sub(
            body,
            "geom",
            name=name,
            class_="part",
            type="capsule",
            size=(p["tube_radius"],),
            fromto=(*a, *b),
            material="strut_tube",
            mass=weight,
        )

    if defect is not None and defect.kind == "bent_tube":
        # A kink at mid-length: the second half turns by bend_deg about x, carrying end b with it.
        mid = np.array([0.0, 0.0, length / 2])
        bend = rot_x(math.radians(defect.bend_deg))
        ends["b"] = mid + bend @ (ends["b"] - mid)
        tube_b = mid + bend @ (tube_b - mid)
        tube(f"{prefix}/tube", tube_a, mid, tube_mass / 2)
        tube(f"{prefix}/tube#1", mid, tube_b, tube_mass / 2)
    else:
        tube(f"{prefix}/tube", tube_a, tube_b, tube_mass)
    axis_b = (ends["b"] - tube_b) / np.linalg.norm(ends["b"] - tube_b)
    spans = {
        "a": (ends["a"] + [0, 0, half], ends["a"] + [0, 0, half + fl]),
        "b": (ends["b"] - axis_b * half, ends["b"] - axis_b * (half + fl)),
    }
    for end, (s0, s1) in spans.items():
        if defect is not None and defect.kind == "missing_end_fitting" and defect.end == end:
            continue
        sub(
            body,
            "geom",
            name=f"{prefix}/fitting_{end}",
            class_="part",
            type="cylinder",
            size=(p["fitting_radius"],),
            fromto=(*s0, *s1),
            material="end_fitting",
            mass=mass * 0.15,
        )
        rivet = s0 + (s1 - s0) * 0.5 + np.array([p["fitting_radius"], 0, 0])
        sub(
            body,
            "geom",
            name=f"{prefix}/rivet_{end}",
            class_="deco",
            type="sphere",
            size=(p["rivet_radius"],),
            pos=rivet,
            material="rivet",
            group=HIDDEN_GROUP,
        )
        # The shank of a head that did not seat, between the fitting and the head; where it shows,
        # and how long it is, follows the shot (tlt_sim.model.rivet_heads). One instance with its head.
        surface = rivet - np.array([p["rivet_radius"], 0, 0])
        sub(
            body,
            "geom",
            name=f"{prefix}/rivet_{end}#1",
            class_="deco",
            type="capsule",
            size=(p["rivet_radius"] / 2,),
            fromto=(*surface, *rivet),
            material="rivet",
            group=HIDDEN_GROUP,
        )
    return ends


def add_part(
    doc: Document,
    mission: Mission,
    parts: dict[str, Any],
    dispenser: str,
    kind: str,
    index: int,
    slot: tuple[np.ndarray, np.ndarray, float],
    defect: Defect | None,
) -> PartInfo:
    """Part ``index`` of ``dispenser`` as a free body in its slot: ``slot`` is the dispenser's
    position and rotation in the world and the slot's height in it. ``parts`` is ``edu.parts``."""
    dpos, drot, z = slot
    bname = names.part_body(dispenser, index)
    w = mission.bay_width
    if kind == "cross_frame":
        local_pos, local_rot = np.array([-w / 2, -w / 2, z]), np.eye(3)
    else:
        length = mission.strut_lengths[kind]
        local_pos, local_rot = np.array([-length / 2, 0.0, z]), rot_y(math.pi / 2)
    wpos, wrot = dpos + drot @ local_pos, drot @ local_rot
    wquat = rotation_to_mujoco_quat(wrot)
    body = sub(doc.world, "body", name=bname, pos=wpos, quat=wquat, gravcomp=1)
    sub(body, "freejoint", name=bname)
    half = parts["corner_size"] / 2
    if kind == "cross_frame":
        grasps = cross_frame_geoms(body, bname, parts, w)
        span = w / 2 - half
        ends = {str(i): np.array([x * w, y * w, 0.0]) for i, (x, y) in enumerate(names.CORNER_XY)}
        length = w
    else:
        ends = strut_geoms(body, bname, parts, length, defect)
        grasps = [(np.array([0.0, 0.0, length / 2]), np.array([0.0, 0.0, 1.0]))]
        span = length / 2 - half - parts["fitting_length"]
    return PartInfo(
        f"{dispenser}/{index}", bname, kind, dispenser, index, length, ends, grasps, wpos, wquat, defect, span
    )


__all__ = ["add_part", "cross_frame_geoms", "strut_geoms"]
