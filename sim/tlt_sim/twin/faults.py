"""A scenario's device faults, applied to the right emulator at the right sim time.

The scenario file (``config/twin/scenarios/*.yaml``, validated by :mod:`tlt_sim.model.scenario`)
lists them under ``faults``; they arrive here as ``Scenario.device_faults``:

* ``servo_failure {link, servo_id, at_s}``: from ``at_s`` that servo is dead: it stops answering
  on its link and its shaft stays where it stood (torque gone);
* ``limit_switch_stuck {switch, pressed, at_s}``: from ``at_s`` lifter limit switch ``switch``
  (0-3 upper, 4-7 lower) reads ``pressed`` whatever the carriage does;
* ``link_drop {link, at_s, duration_s}``: from ``at_s`` for ``duration_s`` (for good when absent)
  nothing answers on that link: the lifter firmware reads and writes nothing, a servo chain answers
  no packet, a UR controller closes its sockets and refuses connections.

:meth:`FaultSchedule.apply_due` is called by the simulation thread after every sync period and
returns what it did, for the log.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from dataclasses import dataclass, field

from tlt_sim.emulators.dynamixel_chain import DynamixelChain
from tlt_sim.twin.devices import TwinDevices


@dataclass(order=True)
class _Event:
    at_s: float
    order: int
    what: str = field(compare=False)
    action: Callable[[], None] = field(compare=False)


class FaultSchedule:
    """Timed device faults for ``devices``; ``applied`` lists (sim time, description) so far."""

    def __init__(self, device_faults: dict[str, list[dict]], devices: TwinDevices) -> None:
        self.devices = devices
        self.applied: list[tuple[float, str]] = []
        self._events: list[_Event] = []
        for fault in device_faults.get("servo_failure", []):
            chain = devices.chains[fault["link"]]
            ids = chain.servos if isinstance(chain, DynamixelChain) else chain.actuators
            if fault["servo_id"] not in ids:
                raise ValueError(
                    f"servo_failure: {fault['link']} has no servo {fault['servo_id']} (ids {sorted(ids)})"
                )
            self._add(
                fault["at_s"],
                f"{fault['link']} servo {fault['servo_id']} fails",
                lambda f=fault: self._fail_servo(f["link"], f["servo_id"]),
            )
        for fault in device_faults.get("limit_switch_stuck", []):
            state = "pressed" if fault["pressed"] else "released"
            self._add(
                fault["at_s"],
                f"lifter limit switch {fault['switch']} stuck {state}",
                lambda f=fault: devices.firmware.force_switch(f["switch"], f["pressed"]),
            )
        for fault in device_faults.get("link_drop", []):
            link, duration = fault["link"], fault.get("duration_s", math.inf)
            self._add(fault["at_s"], f"{link} link drops", lambda link=link, d=duration: self._drop(link, d))
            if math.isfinite(duration) and link != "lifter":  # the firmware restores itself on sim time
                self._add(
                    fault["at_s"] + duration, f"{link} link back", lambda link=link: self._restore(link)
                )

    def _add(self, at_s: float, what: str, action: Callable[[], None]) -> None:
        heapq.heappush(self._events, _Event(at_s, len(self._events), what, action))

    @property
    def pending(self) -> list[tuple[float, str]]:
        return sorted((e.at_s, e.what) for e in self._events)

    def apply_due(self, sim_time: float) -> list[str]:
        """Apply every fault due by ``sim_time``; returns their descriptions."""
        done = []
        while self._events and self._events[0].at_s <= sim_time + 1e-9:
            event = heapq.heappop(self._events)
            event.action()
            self.applied.append((sim_time, event.what))
            done.append(event.what)
        return done

    def _fail_servo(self, link: str, servo_id: int) -> None:
        chain = self.devices.chains[link]
        chain.silence(servo_id)
        if isinstance(chain, DynamixelChain):
            servo = chain.servo(servo_id)
            servo.write(64, b"\x00")  # Torque Enable off: the shaft no longer drives
        else:
            chain.actuator(servo_id).store(0x80, b"\x00")  # Force off

    def _drop(self, link: str, duration_s: float) -> None:
        d = self.devices
        if link == "lifter":
            d.firmware.drop_link(duration_s)
        elif link in d.chains:
            d.chains[link].drop_link(True)
        else:
            d.ur[link].drop_link()

    def _restore(self, link: str) -> None:
        d = self.devices
        if link in d.chains:
            d.chains[link].drop_link(False)
        else:
            d.ur[link].restore_link()


__all__ = ["FaultSchedule"]
