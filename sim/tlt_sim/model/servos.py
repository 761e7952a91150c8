"""The twin's actuated joints as position servos: commanded, rate-limited, read back.

Every actuator of the model is a position servo whose setpoint (its activation) moves at a
velocity set here: towards the commanded target at no more than the joint's rated speed, as the
real controllers do, or at a commanded velocity. :meth:`Servos.update` runs before every physics
step and recomputes those velocities once per control period (about 10 ms), or at once after a
command; with nothing left to move it does no work until the next command.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import mujoco
import numpy as np


class Servos:
    """The servos of ``model``'s actuators on ``data``; ``rated_velocity`` gives each joint's rated
    speed (m/s or rad/s) by name."""

    def __init__(
        self, model: mujoco.MjModel, data: mujoco.MjData, rated_velocity: Callable[[str], float]
    ) -> None:
        self.model, self.data = model, data
        self._actuators = {model.actuator(i).name: i for i in range(model.nu)}
        self._joint_qpos = {n: int(model.jnt_qposadr[model.joint(n).id]) for n in self._actuators}
        self._joint_dof = {n: int(model.jnt_dofadr[model.joint(n).id]) for n in self._actuators}
        nu = model.nu
        self._vmax = np.array([rated_velocity(model.actuator(i).name) for i in range(nu)])
        self._lo = model.actuator_actrange[:, 0].copy()
        self._hi = model.actuator_actrange[:, 1].copy()
        self._actadr = model.actuator_actadr.copy()
        self._target = np.zeros(nu)
        self._velocity = np.zeros(nu)
        self._velocity_mode = np.zeros(nu, dtype=bool)
        self._speed = self._vmax.copy()  # present speed limit of each setpoint (<= rated)
        self._busy = False
        # Setpoint velocities are recomputed every control period (about 10 ms) or on a command.
        self._control_steps = max(1, round(0.01 / model.opt.timestep))
        self._tick = 0

    def reset(self, start: dict[str, float]) -> None:
        """Joints (and their setpoints) at ``start`` (joint name -> position), the others where
        ``data`` has them; no command pending. The caller runs ``mj_forward``."""
        for joint, value in start.items():
            self.data.qpos[self._joint_qpos[joint]] = value
            self.data.act[self._actadr[self._actuators[joint]]] = value
        self._target[:] = self.data.act[self._actadr]
        self._velocity[:] = 0.0
        self._velocity_mode[:] = False
        self._speed[:] = self._vmax
        self._busy = False
        self.data.ctrl[:] = 0.0

    def update(self) -> None:
        """Before every physics step: set the setpoint velocities when a control period starts."""
        if self._tick == 0 and self._busy:
            self._control()
        self._tick = (self._tick + 1) % self._control_steps

    def _control(self) -> None:
        """Set each setpoint's velocity: commanded, or what reaches the target by the next period."""
        period = self._control_steps * self.model.opt.timestep
        act = self.data.act[self._actadr]
        gap = self._target - act
        # minimum/maximum rather than np.clip: the same numbers at a fraction of the call overhead.
        towards = np.minimum(np.maximum(gap / period, -self._speed), self._speed)
        self.data.ctrl[:] = np.where(self._velocity_mode, self._velocity, towards)
        # Nothing left to move: no work until the next command.
        self._busy = bool(self._velocity_mode.any()) or bool((np.abs(gap) > 1e-12).any())
        if not self._busy:
            self.data.ctrl[:] = 0.0

    @property
    def joints(self) -> list[str]:
        """The actuated joints' names, in actuator order."""
        return list(self._actuators)

    def _index(self, joint: str) -> int:
        try:
            return self._actuators[joint]
        except KeyError:
            raise KeyError(f"no actuated joint named {joint!r}") from None

    def command_position(self, joint: str, position: float) -> None:
        """Aim ``joint`` at ``position`` (m or rad), clamped to its range; moves at rated speed."""
        i = self._index(joint)
        if not math.isfinite(position):
            raise ValueError(f"{joint}: position must be finite, got {position}")
        self._target[i] = min(max(position, self._lo[i]), self._hi[i])
        self._velocity_mode[i] = False
        self._speed[i] = self._vmax[i]
        self._wake()

    def command_positions(self, joints: list[str], positions: list[float]) -> None:
        """Move several joints together, each slowed so that all arrive at once (a UR ``movej``)."""
        if len(joints) != len(positions):
            raise ValueError(f"{len(joints)} joints but {len(positions)} positions")
        for joint, position in zip(joints, positions, strict=True):
            self.command_position(joint, position)
        idx = [self._index(j) for j in joints]
        span = np.abs(self._target[idx] - self.data.act[self._actadr[idx]])
        duration = float(np.max(span / self._vmax[idx])) if idx else 0.0
        if duration > 0:
            self._speed[idx] = np.maximum(span / duration, 1e-9)

    def command_velocity(self, joint: str, velocity: float) -> None:
        """Drive ``joint`` at ``velocity`` (clamped to its rated speed) until told otherwise."""
        i = self._index(joint)
        if not math.isfinite(velocity):
            raise ValueError(f"{joint}: velocity must be finite, got {velocity}")
        self._velocity[i] = max(-self._vmax[i], min(self._vmax[i], velocity))
        self._velocity_mode[i] = True
        self._target[i] = self._setpoint_of(i)
        self._wake()

    def hold(self, joint: str) -> None:
        """Stop ``joint`` where its setpoint is now."""
        i = self._index(joint)
        self._velocity_mode[i] = False
        self._target[i] = self._setpoint_of(i)
        self._wake()

    def position(self, joint: str) -> float:
        self._index(joint)
        return float(self.data.qpos[self._joint_qpos[joint]])

    def velocity(self, joint: str) -> float:
        self._index(joint)
        return float(self.data.qvel[self._joint_dof[joint]])

    def effort(self, joint: str) -> float:
        """Force (N) or torque (N m) the joint's actuator applies now."""
        return float(self.data.actuator_force[self._index(joint)])

    def _wake(self) -> None:
        self._busy = True
        self._tick = 0  # act on the command at the next step

    def _setpoint_of(self, i: int) -> float:
        return float(self.data.act[self._actadr[i]])

    def setpoint(self, joint: str) -> float:
        """Where the joint's servo aims now (it moves towards the commanded target)."""
        return self._setpoint_of(self._index(joint))

    def max_velocity(self, joint: str) -> float:
        return float(self._vmax[self._index(joint)])

    def limits(self, joint: str) -> tuple[float, float]:
        i = self._index(joint)
        return float(self._lo[i]), float(self._hi[i])

    def at_target(self, joints: list[str], tolerance: float = 1e-3) -> bool:
        return all(abs(self.position(j) - self._target[self._index(j)]) <= tolerance for j in joints)

    def set_joint_state(self, joint: str, position: float, velocity: float = 0.0) -> None:
        """Place ``joint`` directly (no dynamics) and make that its setpoint; for initial states."""
        i = self._index(joint)
        self.data.qpos[self._joint_qpos[joint]] = position
        self.data.qvel[self._joint_dof[joint]] = velocity
        self.data.act[self._actadr[i]] = self._target[i] = position
        self.data.ctrl[i] = 0.0
        self._velocity_mode[i] = False
        mujoco.mj_forward(self.model, self.data)


__all__ = ["Servos"]
