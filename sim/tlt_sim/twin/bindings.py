"""Bindings between the device emulators and the MuJoCo model: who drives which joint, what reads back.

Every binding has two halves the twin calls once per sync period, from its one simulation thread:
``drive(scene, dt)`` after the emulators have advanced ``dt`` (device state -> model commands) and
``sense(scene, dt)`` after the model has advanced ``dt`` (model state -> device inputs).

* :class:`ServoJointBinding` (Dynamixel and MightyZAP shafts): the servo model is the motor, the
  model joint follows its shaft at the joint's rated speed. When the model joint stalls short of the
  shaft (a jaw closing on a tube, the width carriage on its end stop, a latch on a frame), the
  shaft is put where the joint stopped and an obstacle is set there, so the servo reports the
  stopped position and the current it presses with; the obstacle follows the joint and lifts once
  the goal no longer presses into it, or the joint runs on towards the goal. A count that jumps by
  more than a servo can turn in one period (a reboot keeps only the position within one turn)
  moves the binding's offset, not the joint.
* :class:`LifterBinding`: the firmware's motor velocities drive the lifter joints; encoders are the
  joints' positions (counts = m x counts_per_m), so the limit switches follow the positions.
* :class:`URArmBinding`: the UR controller's motion generator (stepped on sim time, in its own
  process: :mod:`tlt_sim.twin.ur_host`) is the arm's commanded path; the model joints follow it at
  their rated speeds. The controller reports that path, so an arm that a contact holds off it is
  logged by the twin (what the contact is), the one place it can be seen.
* :class:`EEGpioBinding`: the EE limit switch input is the model's width switch; a rising edge on a
  rivet-gun output fires that gun in the model (each joint it reaches noted with its true outcome);
  a gun inserted at a rivet feeder takes a rivet.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from tlt_sim.emulators.gpio_chip import EmulatedGpioChip
from tlt_sim.emulators.lifter_firmware import LifterFirmware
from tlt_sim.model.scene import Scene

log = logging.getLogger("tlt.twin")


class Shaft(Protocol):
    """What a servo model offers the twin: a shaft position in ticks and an obstacle."""

    position: float

    def set_obstacle(self, lower: float | None = None, upper: float | None = None) -> None: ...


@dataclass
class ServoJointBinding:
    """One servo shaft driving one model joint.

    ``to_ticks`` / ``from_ticks`` convert joint units (rad or m) to shaft ticks and back;
    ``goal_ticks`` reads the goal the driver last wrote. ``tolerance`` (joint units) is how far the
    joint may trail the shaft before a stall counts as blocked.
    """

    joint: str
    shaft: Shaft
    to_ticks: Callable[[float], float]
    from_ticks: Callable[[float], float]
    goal_ticks: Callable[[], float]
    tolerance: float
    stall_s: float = 0.03
    blocked: str | None = None  # "upper" / "lower" (in ticks) while an obstacle holds the shaft
    #: ticks added to the shaft's count to get the physical position: a reboot keeps the count
    #: within one turn (the absolute encoder), which changes the count, not the joint
    offset: float = 0.0
    _stalled: float = 0.0
    _commanded: float | None = None
    _last_count: float | None = None

    # No servo turns this far in one sync period: a jump this big is a count reset.
    MAX_TICKS_PER_PERIOD = 1024.0

    def _physical(self, ticks: float) -> float:
        return self.from_ticks(ticks + self.offset)

    def drive(self, scene: Scene, dt: float) -> None:
        count = self.shaft.position
        if self._last_count is not None and abs(count - self._last_count) > self.MAX_TICKS_PER_PERIOD:
            self.offset += self._last_count - count
        self._last_count = count
        # While blocked the joint is sent towards the goal, so it moves on if the obstacle goes.
        target = self._physical(self.goal_ticks() if self.blocked else count)
        if self._commanded is None or abs(target - self._commanded) > 1e-9:
            scene.command_position(self.joint, target)
            self._commanded = target

    def sense(self, scene: Scene, dt: float) -> None:
        q = scene.position(self.joint)
        ticks = self.to_ticks(q) - self.offset
        velocity = scene.velocity(self.joint)
        slow = abs(velocity) < 0.1 * scene.max_velocity(self.joint)
        if self.blocked is None:
            lag = self._physical(self.shaft.position) - q
            self._stalled = self._stalled + dt if abs(lag) > self.tolerance and slow else 0.0
            if self._stalled >= self.stall_s:
                self.blocked = "upper" if self.shaft.position > ticks else "lower"
                self._hold(ticks)
            return
        goal = self.goal_ticks()
        pressing = goal > ticks if self.blocked == "upper" else goal < ticks
        reached = abs(self._physical(goal) - q) <= self.tolerance
        # A joint that runs on towards the goal is no longer held: the shaft takes it over again.
        # Left blocked, it would run on at the model's rated speed while the servo, held where it
        # stopped, pressed at its current limit into an overload (the width carriage: six times the
        # servo's speed, an overload within the second, a whole-system run's EE fault).
        moving_on = not slow and (self._physical(goal) - q) * velocity > 0
        if not pressing or reached or moving_on:
            self.blocked, self._stalled = None, 0.0
            self.shaft.set_obstacle()
            self.shaft.position = self._last_count = ticks
        else:
            self._hold(ticks)

    def _hold(self, ticks: float) -> None:
        self.shaft.position = self._last_count = ticks
        self.shaft.set_obstacle(**{self.blocked: ticks})


@dataclass
class LifterBinding:
    """The lifter firmware's four motors on ``joints`` (counts = metres x ``counts_per_m[i]``)."""

    firmware: LifterFirmware
    joints: list[str]
    counts_per_m: list[float]
    _velocities: list[float] = field(default_factory=list)

    def drive(self, scene: Scene, dt: float) -> None:
        velocities = [v / c for v, c in zip(self.firmware.velocities, self.counts_per_m, strict=True)]
        if velocities != self._velocities:
            for joint, v in zip(self.joints, velocities, strict=True):
                if v:
                    scene.command_velocity(joint, v)
                else:
                    scene.hold(joint)
            self._velocities = velocities

    def sense(self, scene: Scene, dt: float) -> None:
        self.firmware.set_positions(
            [scene.position(joint) * c for joint, c in zip(self.joints, self.counts_per_m, strict=True)]
        )


@dataclass
class URArmBinding:
    """One UR controller's arm (six joints, UR order, read by ``positions``) on the model's arm joints.

    An arm that stands commanded for ``settle_s`` with a model joint more than ``pushed_rad`` off
    its command is logged once, with the contacts of the arm's geoms: the controller reports the
    commanded path, so nothing else shows a strike (a camera housing on a lifter post held an arm
    2 cm off its pose for whole builds, unseen).
    """

    positions: Callable[[], list[float]]
    joints: list[str]
    settle_s: float = 0.5
    pushed_rad: float = 0.005
    _commanded: list[float] = field(default_factory=list)
    _still_s: float = 0.0
    _reported: bool = False

    def drive(self, scene: Scene, dt: float) -> None:
        q = self.positions()
        if q != self._commanded:
            for joint, value, old in zip(self.joints, q, self._commanded or [None] * 6, strict=True):
                if old is None or abs(value - old) > 1e-9:
                    scene.command_position(joint, value)
            self._commanded = q
            self._still_s = 0.0
            self._reported = False

    def sense(self, scene: Scene, dt: float) -> None:
        """The generator's path is what the controller reports (see the module docstring)."""
        if self._reported or not self._commanded:
            return
        self._still_s += dt
        if self._still_s < self.settle_s:
            return
        off = [scene.position(j) - q for j, q in zip(self.joints, self._commanded, strict=True)]
        worst = max(range(len(off)), key=lambda i: abs(off[i]))
        if abs(off[worst]) > self.pushed_rad:
            arm = self.joints[0].split("/", 1)[0]
            touching = ", ".join(f"{a} on {b}" for a, b in scene.truth.contacts_of(f"{arm}/")) or "none"
            log.warning(
                "%s held off its commanded joints (%s %.1f mrad) at %.3f s: contacts %s",
                arm,
                self.joints[worst],
                1000 * off[worst],
                scene.time,
                touching,
            )
        self._reported = True  # one look per commanded pose


@dataclass
class EEGpioBinding:
    """An end effector's GPIO chip: limit switch in, rivet guns out (line -> gun side)."""

    chip: EmulatedGpioChip
    arm: str
    switch_line: int
    switch_active_low: bool
    guns: dict[int, tuple[str, bool]]  # line -> (side "a"/"b", active_low)
    shots: list[tuple[float, str, str]] = field(default_factory=list)  # (sim time, side, outcome)
    loads: list[tuple[float, str]] = field(default_factory=list)  # (sim time, side) of each rivet taken

    def drive(self, scene: Scene, dt: float) -> None:
        for line, level, edges in self.chip.poll():
            if line not in self.guns:
                continue
            side, active_low = self.guns[line]
            on = level != active_low
            # A pulse shorter than a sync period still counts: every second edge was a rising one.
            rising = (edges + 1) // 2 if on else edges // 2
            for _ in range(rising):
                shot = scene.fire_rivet(self.arm, side)
                if shot.joined:
                    outcome = "joined " + ", ".join(shot.joined)
                elif shot.outcomes:
                    outcome = "nothing joined"
                else:
                    outcome = "loaded, nothing in reach" if shot.loaded else "dry shot"
                if shot.outcomes:  # the twin's truth of each joint it reached
                    outcome += " (" + ", ".join(f"{o.equality}: {o.kind}" for o in shot.outcomes) + ")"
                self.shots.append((scene.time, side, outcome))
                log.info("%s rivet gun %s fired at %.3f s: %s", self.arm, side, scene.time, outcome)

    def sense(self, scene: Scene, dt: float) -> None:
        # The guns take rivets mechanically (a gun pushed into a feeder), not through a GPIO line;
        # checked here because this binding is the EE's, once a sync period.
        for side, _ in self.guns.values():
            if not scene.rivet_loaded(self.arm, side) and scene.load_rivet(self.arm, side):
                self.loads.append((scene.time, side))
                log.info("%s rivet gun %s took a rivet at %.3f s", self.arm, side, scene.time)
        pressed = scene.limit_switch(self.arm)
        self.chip.drive(self.switch_line, (not pressed) if self.switch_active_low else pressed)


__all__ = ["EEGpioBinding", "LifterBinding", "ServoJointBinding", "Shaft", "URArmBinding"]
