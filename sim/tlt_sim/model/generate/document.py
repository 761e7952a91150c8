"""The MJCF document being built: its skeleton (compiler, options, visual, assets, defaults, the
floor) and the sections every builder adds to, with the collision bits and geom groups they use.

Collision filtering (contype/conaffinity): the arms (``ARM_BIT``) touch the floor, posts, pedestals
and dispensers; a part that falls (``PART_BIT``, set when it drops) touches only the floor and the
foundation pads; nothing else collides.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from tlt_sim.model.geometry import fmt

ARM_BIT, PART_BIT = 2, 4
HIDDEN_GROUP, RIVET_GROUP = 5, 2
CLASS_COLOURS = {
    "strut_tube": "0.78 0.80 0.83 1",
    "end_fitting": "0.95 0.55 0.10 1",
    "cross_frame": "0.55 0.70 0.85 1",
    "corner_joint": "0.15 0.35 0.75 1",
    "rivet": "0.90 0.10 0.10 1",
}


def sub(parent: ET.Element, tag: str, **attrs: Any) -> ET.Element:
    """A ``tag`` child of ``parent``: attributes that are None are left out, a trailing ``_`` is
    dropped from a name (``class_``), and a value that is not a string is written by :func:`fmt`."""
    el = ET.SubElement(parent, tag)
    for key, value in attrs.items():
        if value is None:
            continue
        key = key.rstrip("_")
        el.set(key, value if isinstance(value, str) else fmt(value))
    return el


class Document:
    """The ``<mujoco>`` root with its skeleton written, and the sections builders add to:
    ``asset``, ``world`` (worldbody), ``contact``, ``actuators`` and ``equality``."""

    def __init__(self, model_name: str, physics: dict[str, Any]) -> None:
        self.root = root = ET.Element("mujoco", model=model_name)
        sub(root, "compiler", angle="radian", autolimits="true")
        sub(root, "option", timestep=physics["timestep"], integrator="implicitfast", cone="elliptic")
        sub(root, "statistic", extent=4.0, center=(0.4, 0.4, 0.9))
        visual = sub(root, "visual")
        sub(visual, "global", offwidth=1280, offheight=960)
        # Coarser tessellation of round geoms: CPU rendering cost is mostly their triangles.
        sub(visual, "quality", shadowsize=2048, numslices=14, numstacks=6, numquads=1)
        sub(visual, "map", znear=0.004, zfar=12.0)
        sub(visual, "headlight", ambient=(0.35, 0.35, 0.35), diffuse=(0.55, 0.55, 0.55))
        self.asset = sub(root, "asset")
        sub(
            self.asset,
            "texture",
            name="grid",
            type="2d",
            builtin="checker",
            rgb1=(0.32, 0.34, 0.36),
            rgb2=(0.28, 0.30, 0.32),
            width=256,
            height=256,
        )
        sub(self.asset, "material", name="floor", texture="grid", texrepeat=(8, 8), reflectance=0.0)
        for cls, rgba in CLASS_COLOURS.items():
            sub(self.asset, "material", name=cls, rgba=rgba, specular=0.4)
        self._defaults()
        self.world = sub(root, "worldbody")
        sub(
            self.world,
            "light",
            name="sun",
            pos=(0.4, 0.4, 5.0),
            dir=(0.1, 0.1, -1.0),
            directional="true",
            diffuse=(0.6, 0.6, 0.6),
            castshadow="false",
        )
        sub(
            self.world,
            "geom",
            name="floor",
            type="plane",
            size=(6, 6, 0.1),
            material="floor",
            contype=1,
            conaffinity=1 | ARM_BIT | PART_BIT,
        )
        self.contact = sub(root, "contact")
        self.actuators = sub(root, "actuator")
        self.equality = sub(root, "equality")

    def _defaults(self) -> None:
        d = sub(self.root, "default")
        env = sub(d, "default", class_="env")
        sub(env, "geom", contype=0, conaffinity=ARM_BIT, rgba=(0.45, 0.47, 0.5, 1))
        mech = sub(d, "default", class_="mech")
        sub(mech, "geom", contype=0, conaffinity=0, rgba=(0.25, 0.25, 0.28, 1))
        arm = sub(d, "default", class_="arm")
        sub(arm, "geom", contype=ARM_BIT, conaffinity=0, rgba=(0.55, 0.65, 0.75, 1))
        part = sub(d, "default", class_="part")
        # Parts collide with nothing until they fall (the scene then sets contype to PART_BIT):
        # a hundred resting parts would otherwise cost most of each step's collision search.
        sub(part, "geom", contype=0, conaffinity=0, condim=3)
        deco = sub(d, "default", class_="deco")
        sub(deco, "geom", contype=0, conaffinity=0, mass=0)

    def actuator(self, joint: str, kp: float, kv: float, force: float, span: tuple[float, float]) -> None:
        """A servo on ``joint``: an integrated-velocity actuator."""
        # ctrl is the setpoint's velocity and MuJoCo integrates the setpoint (act, kept within
        # span) every step, so Python only sets velocities at the control rate (see Scene.step).
        sub(
            self.actuators,
            "intvelocity",
            name=joint,
            joint=joint,
            kp=kp,
            kv=kv,
            forcerange=(-force, force),
            actrange=span,
        )

    def write(self, path: Path) -> None:
        """Indent the document and write it to ``path`` (its folder is made if missing)."""
        ET.indent(self.root)
        path.parent.mkdir(parents=True, exist_ok=True)
        ET.ElementTree(self.root).write(path, encoding="unicode")


__all__ = ["ARM_BIT", "CLASS_COLOURS", "HIDDEN_GROUP", "PART_BIT", "RIVET_GROUP", "Document", "sub"]
