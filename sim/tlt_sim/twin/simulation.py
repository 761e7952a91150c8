"""The twin's simulation loop body: the model, every emulator bound to it, the scenario's device faults.

:class:`Twin` owns sim time. One :meth:`tick` (one sync period, ``run.yaml`` ``sync_period_s``):

1. every emulator advances by the period (lifter firmware state machine and watchdog, servo
   shafts, UR motion generators);
2. the bindings turn device state into model commands;
3. the model steps the period;
4. the bindings feed the model back (encoders, limit switches, blocked shafts, the EE switch);
5. scenario device faults due by the new sim time are applied.

Each part an arm lets go of is judged against the mission's places by the model's truth
(:meth:`Scene.placement`): logged, and appended to ``<run_dir>/placements.jsonl`` (one JSON object
a release: arm, sim time, part, member, centre and angle error, each joint point's error), so a
run's record says where every part really went, beside what vision measured. Each joint a rivet
shot reaches is recorded likewise with its true outcome (:mod:`tlt_sim.model.rivet_outcomes`: good,
or how it failed, and why) in ``<run_dir>/rivets.jsonl``: for judging a run, never read by the
system under test.

Only the thread that calls :meth:`tick` touches the Scene. The emulators' pty and socket threads
answer the drivers in between, under the emulators' own locks.

**Drivers keep pace at any real-time factor.** Every driver runs its control loop on ROS time
(sim time from /clock): the lifter driver commands the firmware every 20 ms and the firmware zeroes
the motors after 40 ms of sim time without a command; the servo drivers write goals every 10 to
50 ms and their trajectory controllers check path tolerances against sim time. When the simulation
runs faster than a driver can turn its cycle around (``--rtf 0``, or a loaded machine), sim time
would run away from the driver through no fault of its own. :meth:`hold_for_drivers` therefore
keeps sim time at most a lead (:func:`lead_s`: ``driver_lead_s``, at least 1.5 driver periods,
below the lifter's watchdog) ahead of the last bytes each serial link received:
before a period that would pass that point it waits for the late links' next bytes, for at most
``driver_wait_s`` of wall time. A link whose driver stopped talking (dead, in ERROR between
reconnect attempts) is waited for once, then ignored until it talks again, so a driver that really
stops still trips the lifter watchdog. The UR controllers are not held for: their RTDE stream and
ur-rtde's handshakes run on wall time, and the arm's motion generator on sim time.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tlt_common.json_lines import JsonLinesWriter
from tlt_sim.model.scene import Scene
from tlt_sim.twin.devices import TwinDevices
from tlt_sim.twin.faults import FaultSchedule
from tlt_sim.twin.settings import TwinSettings

log = logging.getLogger("tlt.twin")


class Twin:
    """The model with its devices; :meth:`start` serves the links, :meth:`close` ends everything."""

    def __init__(self, scene: Scene, settings: TwinSettings, run_dir: str | Path) -> None:
        self.scene = scene
        self.settings = settings
        self.run_dir = Path(run_dir)
        self.devices = TwinDevices(scene, settings, self.run_dir)
        self.faults = FaultSchedule(scene.scenario.device_faults, self.devices)
        self.holds = 0  # times sim time waited for a driver
        self._links = {
            name: _Link(name, lead_s(period, settings.driver_lead_s, self.devices.driver_watchdogs.get(name)))
            for name, period in self.devices.driver_periods.items()
        }
        self._closed = False
        self.placements_path = self.run_dir / "placements.jsonl"
        self._placements = JsonLinesWriter(self.placements_path)
        self.rivets_path = self.run_dir / "rivets.jsonl"
        self._rivets = JsonLinesWriter(self.rivets_path)

    def start(self) -> None:
        """Serve every device link; faults due at time 0 apply at once."""
        self.devices.start()
        self._apply_faults()

    def close(self) -> None:
        """Withdraw the links and stop every emulator (also when never started)."""
        if not self._closed:
            self._closed = True
            self.devices.close()

    def __enter__(self) -> Twin:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def sim_time(self) -> float:
        return self.scene.time

    def tick(self) -> float:
        """Advance one sync period; returns the new sim time."""
        dt = self.settings.sync_period_s
        self._note_traffic()  # bytes that came in since the last period came in at this time
        self.devices.advance(dt)
        self.devices.drive(dt)
        self.scene.advance(dt)
        self._note_releases()
        self._note_rivets()
        self.devices.sense(dt)
        self._apply_faults()
        self._note_traffic()
        return self.scene.time

    def run_for(self, seconds: float) -> None:
        """Tick for ``seconds`` of sim time as fast as possible (tests, data generation)."""
        end = self.scene.time + seconds - 1e-9
        while self.scene.time < end:
            self.tick()

    def _note_releases(self) -> None:
        releases = self.scene.assembly.releases
        while releases:
            release = releases.pop(0)
            placed = self.scene.placement(release)
            log.info("%s released %s at %.3f s", release.arm, placed.describe(), release.time)
            record = {"arm": release.arm, "time": release.time, **placed.as_dict()}
            try:
                self._placements.append(record)
            except OSError as exc:
                log.warning("cannot record a placement in %s: %s", self.placements_path, exc)

    def _note_rivets(self) -> None:
        outcomes = self.scene.assembly.rivet_log
        while outcomes:
            joint = outcomes.pop(0)
            (log.info if joint.good else log.warning)("rivet %s at %.3f s", joint.describe(), joint.time)
            try:
                self._rivets.append(joint.as_dict())
            except OSError as exc:
                log.warning("cannot record a rivet in %s: %s", self.rivets_path, exc)

    def _apply_faults(self) -> None:
        for what in self.faults.apply_due(self.scene.time):
            log.warning("device fault at %.3f s: %s", self.scene.time, what)

    def _note_traffic(self) -> None:
        for name, count in self.devices.link_traffic().items():
            link = self._links[name]
            if count != link.count:
                link.count, link.since = count, self.scene.time

    def hold_for_drivers(
        self, clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep
    ) -> bool:
        """Before the next period, wait (bounded) for every link that would fall behind; True if held."""
        wait_s = self.settings.driver_wait_s
        if wait_s <= 0:
            return False
        self._note_traffic()
        t_next = self.scene.time + self.settings.sync_period_s
        late = [
            link
            for link in self._links.values()
            if link.count > 0 and link.given_up_on != link.count and t_next > link.since + link.lead_s + 1e-9
        ]
        if not late:
            return False
        deadline = clock() + wait_s
        while True:
            traffic = self.devices.link_traffic()
            waiting = [link for link in late if traffic[link.name] == link.count]
            if not waiting:
                break
            if clock() >= deadline:
                for link in waiting:
                    link.given_up_on = link.count
                    log.warning(
                        "%s driver silent for %.2f s of wall time: not waiting for it", link.name, wait_s
                    )
                break
            sleep(0.0005)
        self.holds += 1
        self._note_traffic()
        return True


# A link may always fall this many of its driver's periods behind sim time before the twin waits.
LEAD_PERIODS = 1.5
# A link with a watchdog never falls further behind than this fraction of its timeout.
WATCHDOG_MARGIN = 0.75


def lead_s(period_s: float, driver_lead_s: float, watchdog_s: float | None) -> float:
    """How far sim time may run ahead of a link's last bytes before the twin waits for its driver.

    ``driver_lead_s`` (run.yaml) or 1.5 driver periods, whichever is longer; for a device with a
    watchdog (the lifter firmware's, two command periods), at most 3/4 of its timeout, so a driver
    that is only late never trips it.
    """
    lead = max(LEAD_PERIODS * period_s, driver_lead_s)
    return lead if watchdog_s is None else min(lead, WATCHDOG_MARGIN * watchdog_s)


@dataclass
class _Link:
    name: str
    lead_s: float
    count: int = 0
    since: float = 0.0  # sim time its traffic last changed
    given_up_on: int | None = None


__all__ = ["LEAD_PERIODS", "WATCHDOG_MARGIN", "Twin", "lead_s"]
