"""At any real-time factor sim time waits for a late driver, so the lifter watchdog trips only when
the driver really stops commanding."""

from __future__ import annotations

import threading

import pytest
from tlt_sim.emulators import dynamixel_protocol as proto
from tlt_sim.twin.simulation import lead_s

from tlt_drivers.lifter.protocol import FirmwareState, Mode, VelocityCommand

SYNC = 0.01  # the twins here tick in 10 ms sync periods: the steps below count them


class FakeWall:
    def __init__(self) -> None:
        self.now = 0.0

    def clock(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.now += s


def _command(fw, seq: int = 1) -> None:
    fw.receive(VelocityCommand((0, 0, 0, 0)).encode(seq))


def _crs_control(twin):
    twin.run_for(0.6)
    fw = twin.devices.firmware
    assert fw.request_mode(Mode.CRS_CONTROL).name == "ACCEPTED"
    _command(fw)
    twin.tick()
    return fw


def test_sim_time_waits_for_a_late_lifter_command(make_twin):
    twin = make_twin(driver_wait_s=5.0, sync_period_s=SYNC)
    fw = _crs_control(twin)
    twin.tick()
    assert not twin.hold_for_drivers(), "10 ms after a command: no need to wait"
    twin.tick()
    # 20 ms after the last command the driver is due; its command comes 50 ms late by wall clock.
    sender = threading.Timer(0.05, _command, (fw, 2))
    sender.start()
    before = twin.scene.time
    assert twin.hold_for_drivers()
    sender.join()
    assert twin.scene.time == before and fw.frames_received == 2
    for _ in range(3):
        twin.tick()
    assert not fw.watchdog_tripped


def test_a_driver_that_stopped_still_trips_the_watchdog(make_twin):
    twin = make_twin(driver_wait_s=0.25, sync_period_s=SYNC)
    fw = _crs_control(twin)
    wall = FakeWall()
    held = 0
    for _ in range(20):
        held += twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep)
        twin.tick()
    assert held == 1, "the twin waits once for the missing command, then lets time run"
    assert 0.25 <= wall.now < 0.3
    assert fw.watchdog_tripped and fw.state == FirmwareState.CRS_CONTROL
    # Once the driver talks again, it is kept pace with again.
    _command(fw, 5)
    twin.tick()
    twin.tick()
    twin.tick()
    assert twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep)


def test_servo_links_are_kept_pace_with_and_silent_links_ignored(make_twin):
    twin = make_twin(driver_wait_s=0.1, driver_lead_s=0.0, sync_period_s=SYNC)
    chain = twin.devices.chains["active_grippers"]  # its driver runs at 100 Hz: 15 ms of lead
    wall = FakeWall()
    assert not twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep), "no driver has talked yet"
    ping = proto.build_packet(1, proto.PING)
    chain.handle(ping)
    assert not twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep)
    twin.tick()

    def answer_soon(s: float) -> None:  # the driver's next packet arrives 2 ms (wall) into the wait
        wall.sleep(s)
        if wall.now >= 0.002 and chain.packets_seen == 1:
            chain.handle(ping)

    assert twin.hold_for_drivers(clock=wall.clock, sleep=answer_soon)
    assert 0.002 <= wall.now < 0.01, "released as soon as the packet came"
    twin.tick()
    start = wall.now
    assert twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep), "silent now: waited for once"
    assert wall.now - start >= 0.1
    twin.tick()
    assert not twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep), "given up until it talks again"


def test_the_lead_is_driver_lead_s_or_longer_and_below_a_watchdog():
    assert lead_s(0.01, 0.05, None) == pytest.approx(0.05), "a 100 Hz servo chain: 5 periods"
    assert lead_s(0.05, 0.05, None) == pytest.approx(0.075), "a 20 Hz chain: never under 1.5 periods"
    assert lead_s(0.02, 0.05, 0.04) == pytest.approx(0.03), "the lifter: 3/4 of its 40 ms watchdog"


def test_a_servo_link_may_lag_driver_lead_s_before_sim_time_waits(make_twin):
    twin = make_twin(driver_wait_s=0.1, driver_lead_s=0.05, sync_period_s=SYNC)
    chain = twin.devices.chains["active_grippers"]  # 100 Hz, no watchdog: 50 ms of lead
    wall = FakeWall()
    chain.handle(proto.build_packet(1, proto.PING))
    for _ in range(5):  # up to 50 ms after its last packet
        assert not twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep)
        twin.tick()
    assert twin.hold_for_drivers(clock=wall.clock, sleep=wall.sleep), "the next period would pass 50 ms"
