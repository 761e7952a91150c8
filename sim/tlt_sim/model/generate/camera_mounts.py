"""The ZED camera mounts: a turning mount on each of the lifter posts named by
:data:`names.ZED_CORNERS`, above the top level, with its camera looking down at the tower."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from tlt_common.geometry.transforms import rot_z, rotation_to_mujoco_quat
from tlt_sim.model import names
from tlt_sim.model.generate.document import Document, sub
from tlt_sim.model.generate.layout import TowerLayout
from tlt_sim.model.geometry import look_at_xyaxes


def add_camera_mounts(
    doc: Document, layout: TowerLayout, frame: ET.Element, mounts: dict[str, Any], zed_fovy_deg: float
) -> None:
    """A mount and its ZED camera on the lifter ``frame`` at each of :data:`names.ZED_CORNERS`;
    ``mounts`` is ``edu.camera_mounts``."""
    for n, corner in enumerate(names.ZED_CORNERS):
        _camera_mount(doc, layout, frame, n, corner, mounts, zed_fovy_deg)


def _camera_mount(
    doc: Document,
    layout: TowerLayout,
    frame: ET.Element,
    n: int,
    corner: int,
    cm: dict[str, Any],
    zed_fovy_deg: float,
) -> None:
    p, o = layout.post_xy[corner], layout.diagonal[corner]
    z = layout.top_level + cm["height"]
    pos = p + o * 0.06
    sub(
        frame,
        "geom",
        name=f"{names.camera_mount(n)}/arm",
        class_="mech",
        type="box",
        size=(0.03, 0.03, 0.02),
        pos=(p[0] + o[0] * 0.03, p[1] + o[1] * 0.03, z - 0.04),
    )
    mount = sub(frame, "body", name=names.camera_mount(n), pos=(pos[0], pos[1], z))
    joint = names.camera_mount(n)
    sub(
        mount,
        "joint",
        name=joint,
        type="hinge",
        axis=(0, 0, 1),
        range=cm["range"],
        armature=0.05,
        damping=0.3,
    )
    # At inward_angle the camera looks at the tower axis; the mount turns it by (q - inward_angle).
    pitch = math.radians(cm["pitch_deg"])
    heading = math.atan2(-o[1], -o[0]) - cm["inward_angle"]
    flat = np.array([math.cos(heading), math.sin(heading)]) * math.cos(pitch)
    look = np.array([flat[0], flat[1], -math.sin(pitch)])
    sub(
        mount,
        "geom",
        class_="mech",
        type="box",
        size=(0.03, 0.09, 0.015),
        mass=0.17,
        quat=rotation_to_mujoco_quat(rot_z(heading)),
        rgba=(0.1, 0.1, 0.1, 1),
    )
    sub(
        mount,
        "camera",
        name=names.zed_camera(n),
        pos=tuple(look * 0.04),
        xyaxes=look_at_xyaxes(look),
        fovy=zed_fovy_deg,
    )
    doc.actuator(joint, 30.0, 1.5, 8.4, tuple(cm["range"]))


__all__ = ["add_camera_mounts"]
