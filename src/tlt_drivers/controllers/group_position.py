"""Joint group position controller logic in the manner of ros2_control's JointGroupPositionController.

A command is one position per joint, in the controller's joint order (the layout of a
``std_msgs/Float64MultiArray`` on its command topic). :meth:`JointGroupPositionController.set_command`
accepts it only if it has the right length, every value is a finite number inside that joint's
limits and the ``motion_gate`` (calibration, faults) allows motion; otherwise it raises
:class:`CommandRejected` naming the joint and the limit, and the previous command stays in force.
:meth:`update` returns the command to send each cycle (the held position until a command arrives).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence


class CommandRejected(ValueError):
    """A group position command that was not applied; the message says why."""


class JointGroupPositionController:
    """Position commands for ``joints`` with ``limits[name] = (lower, upper)``."""

    def __init__(
        self,
        joints: Sequence[str],
        limits: Mapping[str, tuple[float, float]],
        *,
        motion_gate: Callable[[], str | None] | None = None,
    ) -> None:
        self.joints = list(joints)
        self.limits = dict(limits)
        self.motion_gate = motion_gate
        self.target: dict[str, float] = {}
        self.rejections = 0
        self.last_rejection = ""

    def check(self, values: Sequence[float]) -> None:
        """Raise :class:`CommandRejected` unless ``values`` is a command this controller would apply."""
        if len(values) != len(self.joints):
            raise CommandRejected(
                f"command has {len(values)} value(s) for {len(self.joints)} joint(s) {self.joints}"
            )
        for name, value in zip(self.joints, values, strict=True):
            lower, upper = self.limits[name]
            if not math.isfinite(value):
                raise CommandRejected(f"joint {name!r}: command {value} is not a number")
            if value < lower:
                raise CommandRejected(f"joint {name!r}: command {value} is below the lower limit {lower}")
            if value > upper:
                raise CommandRejected(f"joint {name!r}: command {value} is above the upper limit {upper}")
        if self.motion_gate is not None:
            refusal = self.motion_gate()
            if refusal:
                raise CommandRejected(refusal)

    def set_command(self, values: Sequence[float]) -> None:
        """Apply ``values`` or raise :class:`CommandRejected` (the previous command stays)."""
        try:
            self.check(values)
        except CommandRejected as exc:
            self.rejections += 1
            self.last_rejection = str(exc)
            raise
        self.target = dict(zip(self.joints, (float(v) for v in values), strict=True))

    def reset_hold(self, actual: Mapping[str, float]) -> None:
        """Hold the actual positions (after activation, recovery or calibration)."""
        self.target = {name: actual[name] for name in self.joints if name in actual}

    def update(self, actual: Mapping[str, float]) -> dict[str, float]:
        """Position command for every joint."""
        for name in self.joints:
            self.target.setdefault(name, actual.get(name, 0.0))
        return dict(self.target)
