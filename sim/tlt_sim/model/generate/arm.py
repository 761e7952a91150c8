"""A UR10e on its pedestal: six links on the DH table of :mod:`tlt_common.geometry.ur10e`, a servo per
joint, and the end effector on the flange."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tlt_common.geometry import ur10e
from tlt_common.geometry.transforms import rot_x, rot_z, rotation_to_mujoco_quat
from tlt_sim.model import names
from tlt_sim.model.generate.document import Document, sub
from tlt_sim.model.generate.end_effector import add_end_effector


def add_arm(doc: Document, arm: str, edu: dict[str, Any]) -> None:
    """Arm ``arm`` (its base, pedestal, links and joints, then its end effector).

    Reads ``arms``, ``end_effector``, ``parts.tube_radius`` and ``cameras`` of ``edu``.
    """
    cfg, arms = edu["arms"][arm], edu["arms"]
    base = np.asarray(cfg["base"], dtype=float)
    ped = cfg["pedestal_height"]
    parent = sub(
        doc.world,
        "body",
        name=f"{arm}/base",
        pos=(base[0], base[1], base[2] + ped),
        quat=rotation_to_mujoco_quat(rot_z(math.radians(cfg["yaw_deg"]))),
    )
    if ped > 0:  # in the base body, so the first link (its child) never collides with it
        sub(
            parent,
            "geom",
            name=f"{arm}/pedestal",
            class_="env",
            type="cylinder",
            size=(0.09, ped / 2),
            pos=(0, 0, -ped / 2),
        )
    sub(parent, "geom", class_="arm", type="cylinder", size=(0.095, 0.03), pos=(0, 0, 0.03), mass=2.0)
    # The base is welded to the world, so MuJoCo's parent filter does not spare the first link.
    sub(doc.contact, "exclude", body1=f"{arm}/base", body2=f"{arm}/link_1")
    pos, quat = np.zeros(3), np.array([1.0, 0, 0, 0])
    for i in range(6):
        link = sub(parent, "body", name=f"{arm}/link_{i + 1}", pos=pos, quat=quat, gravcomp=1)
        joint = names.arm_joint(arm, i)
        sub(
            link,
            "joint",
            name=joint,
            type="hinge",
            axis=(0, 0, 1),
            range=(-ur10e.POSITION_LIMIT, ur10e.POSITION_LIMIT),
            armature=arms["armature"],
            damping=2.0,
        )
        sub(
            link,
            "inertial",
            pos=ur10e.COM[i],
            mass=ur10e.MASS[i],
            diaginertia=(ur10e.MASS[i] * 0.01,) * 3,
        )
        radius = ur10e.LINK_RADIUS[i]
        end = np.array([ur10e.A[i], 0.0, ur10e.D[i]])
        sub(link, "geom", class_="arm", type="cylinder", size=(radius, radius * 0.9), mass=0)
        if np.linalg.norm(end) > 1e-6:
            sub(
                link,
                "geom",
                name=f"{arm}/link_{i + 1}/capsule",
                class_="arm",
                type="capsule",
                size=(radius * 0.8,),
                fromto=(0, 0, 0, *end),
                mass=0,
            )
        doc.actuator(
            joint,
            arms["kp"],
            arms["kv"],
            ur10e.TORQUE_LIMIT[i],
            (-ur10e.POSITION_LIMIT, ur10e.POSITION_LIMIT),
        )
        parent = link
        pos, quat = end, rotation_to_mujoco_quat(rot_x(ur10e.ALPHA[i]))
    flange = sub(parent, "body", name=names.ee_body(arm), pos=pos, quat=quat, gravcomp=1)
    sub(flange, "site", name=f"{arm}/flange", size=(0.01,))
    add_end_effector(doc, arm, flange, edu["end_effector"], edu["parts"]["tube_radius"], edu["cameras"])


__all__ = ["add_arm"]
