"""Damped least-squares inverse kinematics of a twin arm, on the compiled model itself.

Used to pose the arms for tests, pictures and synthetic data (the ARS plans with its own
planner). :func:`solve` finds joint angles that put a point fixed in the EE frame at a world
position with the EE frame at a world rotation, or returns ``None`` when no seed converges;
:func:`solutions` gives the distinct ones from several seeds, and :func:`path_clear` says whether
the straight joint-space move between two configurations stays out of contact.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from tlt_sim.model import names


def _rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Axis-angle vector of the rotation taking ``current`` to ``target`` (world frame)."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, (target @ current.T).reshape(9))
    vel = np.zeros(3)
    mujoco.mju_quat2Vel(vel, quat, 1.0)
    return vel


def solve(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    arm: str,
    position: Sequence[float],
    rotation: np.ndarray,
    point: Sequence[float] = (0.0, 0.0, 0.0),
    seeds: Sequence[Sequence[float]] = (),
    tolerance: float = 1e-4,
    iterations: int = 200,
) -> np.ndarray | None:
    """Six joint angles putting EE-frame ``point`` at ``position`` with EE rotation ``rotation``.

    ``qpos`` is the model state to start from (the arm's present angles are the first seed).
    """
    data = mujoco.MjData(model)
    target_p, target_r = np.asarray(position, dtype=float), np.asarray(rotation, dtype=float)
    point = np.asarray(point, dtype=float)
    for q in _converge(model, data, qpos, arm, target_p, target_r, point, seeds, tolerance, iterations):
        return q
    return None


SEEDS = (
    (0.0, -1.57, 1.57, -1.57, -1.57, 0.0),
    (0.0, -1.2, 1.8, -2.2, -1.57, 0.0),
    (1.57, -1.2, 1.8, -2.2, -1.57, 0.0),
    (-1.57, -1.2, 1.8, -2.2, -1.57, 0.0),
    (3.14, -1.2, 1.8, -2.2, -1.57, 0.0),
    (0.0, -1.9, -1.8, -1.0, 1.57, 0.0),
    (1.57, -1.9, -1.8, -1.0, 1.57, 0.0),
    (-1.57, -1.9, -1.8, -1.0, 1.57, 0.0),
    (3.14, -1.9, -1.8, -1.0, 1.57, 0.0),
)


def solutions(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    arm: str,
    position: Sequence[float],
    rotation: np.ndarray,
    point: Sequence[float] = (0.0, 0.0, 0.0),
    seeds: Sequence[Sequence[float]] = SEEDS,
) -> list[np.ndarray]:
    """Distinct joint solutions for the pose, from the present angles and each seed."""
    data = mujoco.MjData(model)
    found: list[np.ndarray] = []
    for q in _converge(
        model,
        data,
        qpos,
        arm,
        np.asarray(position, dtype=float),
        np.asarray(rotation, dtype=float),
        np.asarray(point, dtype=float),
        seeds,
        1e-4,
        200,
    ):
        if all(np.abs(q - f).max() > 1e-2 for f in found):
            found.append(q)
    return found


def path_clear(
    model: mujoco.MjModel, qpos: np.ndarray, arm: str, q_to: Sequence[float], samples: int = 16
) -> bool:
    """True if moving ``arm`` in a straight joint line from ``qpos`` to ``q_to`` touches nothing."""
    data = mujoco.MjData(model)
    qadr = np.array([model.joint(n).qposadr[0] for n in names.arm_joints(arm)])
    prefix = f"{arm}/"
    start = qpos[qadr].copy()
    touching: set[tuple[int, int]] | None = None  # contacts at the start may be left, not made
    for f in np.linspace(0.0, 1.0, samples):
        data.qpos[:] = qpos
        data.qpos[qadr] = start + f * (np.asarray(q_to) - start)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        pairs = set()
        for c in data.contact[: data.ncon]:
            bodies = (
                model.body(model.geom_bodyid[c.geom1]).name,
                model.body(model.geom_bodyid[c.geom2]).name,
            )
            if any(b.startswith(prefix) for b in bodies) and c.dist < 0:
                pairs.add((int(c.geom1), int(c.geom2)))
        if touching is None:
            touching = pairs
        elif pairs - touching:
            return False
    return True


def _converge(model, data, qpos, arm, target_p, target_r, point, seeds, tolerance, iterations):
    joints = [model.joint(n) for n in names.arm_joints(arm)]
    qadr = np.array([j.qposadr[0] for j in joints])
    dofs = np.array([j.dofadr[0] for j in joints])
    lo, hi = model.jnt_range[[j.id for j in joints]].T
    body = model.body(names.ee_body(arm)).id
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    starts = [qpos[qadr].copy(), *[np.asarray(s, dtype=float) for s in seeds]]
    for start in starts:
        data.qpos[:] = qpos
        data.qpos[qadr] = start
        for _ in range(iterations):
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            r = data.xmat[body].reshape(3, 3)
            p = data.xpos[body] + r @ point
            err = np.concatenate([target_p - p, _rotation_error(target_r, r)])
            if np.linalg.norm(err[:3]) < tolerance and np.linalg.norm(err[3:]) < 10 * tolerance:
                # The same pose by whole turns nearest the present angles: the shortest move.
                q = data.qpos[qadr].copy()
                near = qpos[qadr] + np.mod(q - qpos[qadr] + np.pi, 2 * np.pi) - np.pi
                yield np.where((near >= lo) & (near <= hi), near, q)
                break
            mujoco.mj_jac(model, data, jacp, jacr, p, body)
            jac = np.vstack([jacp[:, dofs], jacr[:, dofs]])
            step = jac.T @ np.linalg.solve(jac @ jac.T + 1e-4 * np.eye(6), err)
            scale = min(1.0, 0.5 / max(np.abs(step).max(), 1e-12))
            data.qpos[qadr] = np.clip(data.qpos[qadr] + scale * step, lo, hi)
    return None


# A posture with the tool down and the whole EE above the lifter posts (1.5 m) for a base on a
# 0.55 m pedestal: shoulder lift, elbow, wrist 1 and wrist 2; pan and wrist 3 are free.
CARRY = (-1.7, 0.0, 0.129, -np.pi / 2)


def _with(qpos: np.ndarray, qadr: np.ndarray, q: Sequence[float]) -> np.ndarray:
    out = qpos.copy()
    out[qadr] = q
    return out


def plan(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    arm: str,
    position: Sequence[float],
    rotation: np.ndarray,
    point: Sequence[float] = (0.0, 0.0, 0.0),
    carry: Sequence[float] = CARRY,
) -> list[np.ndarray] | None:
    """Joint waypoints to the pose: straight if clear, else up to ``carry``, around, and down.

    Tries each IK solution, nearest first; ``None`` when no solution has a clear way. A stand-in
    for tests and data generation, not the ARS motion planner.
    """
    qadr = np.array([model.joint(n).qposadr[0] for n in names.arm_joints(arm)])
    here = qpos[qadr].copy()
    options = sorted(
        solutions(model, qpos, arm, position, rotation, point), key=lambda q: np.abs(q - here).max()
    )
    for q in options:
        if path_clear(model, qpos, arm, q):
            return [q]
    for q in options:
        up = np.array([here[0], *carry, here[5]])
        over = np.array([q[0], *carry, q[5]])
        legs = ((qpos, up), (_with(qpos, qadr, up), over), (_with(qpos, qadr, over), q))
        if all(path_clear(model, start, arm, end) for start, end in legs):
            return [up, over, q]
    return None


__all__ = ["CARRY", "SEEDS", "path_clear", "plan", "solutions", "solve"]
