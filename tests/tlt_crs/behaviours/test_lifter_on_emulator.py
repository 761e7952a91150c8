"""Lifter CRS Control and a lifter move (steps of Figs. 18 and 19) against the real lifter driver node
(``tlt_drivers.lifter.node``) talking over a pseudo-terminal to the lifter firmware emulator
(``tlt_sim.emulators.lifter_main``): real bytes, real LifterState encoders, real SetLifterMode."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import py_trees
import pytest
import rclpy
from py_trees.common import Status

from tlt_common.ros.isolation import isolate
from tlt_crs.behaviours.actuators import Actuators


@pytest.fixture
def lifter_domain(tmp_path):
    """Emulator and driver processes in a ROS domain of their own, and rclpy initialised in it."""
    env = dict(os.environ)
    domain = isolate(env)
    link = tmp_path / "lifter-pty"
    emulator = subprocess.Popen(
        [sys.executable, "-m", "tlt_sim.emulators.lifter_main", "--link", str(link)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 20
    while not link.exists():
        assert time.monotonic() < deadline and emulator.poll() is None, "lifter emulator did not start"
        time.sleep(0.05)
    driver = subprocess.Popen(
        [sys.executable, "-m", "tlt_drivers.lifter.node", "--port", str(link)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    rclpy.init(domain_id=domain)
    py_trees.blackboard.Blackboard.clear()
    try:
        yield
    finally:
        py_trees.blackboard.Blackboard.clear()
        rclpy.try_shutdown()
        for proc in (driver, emulator):
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def test_crs_control_and_lifter_move_on_the_driver_and_firmware_emulator(lifter_domain, crs, tmp_path):
    rig = crs.Rig(with_drivers=False, with_ars=False)
    try:
        ctx = crs.make_context(rig, crs.fast_config(tmp_path, service_s=10.0, actuator_s=20.0))
        actuators = Actuators(ctx)
        control = actuators.lifter_crs_control()
        crs.wait_for(lambda: ctx.cache.latest("/lifter/state") is not None, timeout=20.0, what="lifter state")
        state = ctx.cache.latest("/lifter/state")[0]
        assert state.link_ok and state.state != 2
        assert crs.tick_until(control, timeout=20.0) == Status.SUCCESS
        assert ctx.cache.latest("/lifter/state")[0].state == 2  # CRS Control, from the firmware

        start = max(ctx.cache.latest("/lifter/state")[0].encoder_positions)
        target = round(start + 0.01, 4)
        ctx.board.set("lifter_speed", 0.02)
        move = actuators.lifter_move("Raise", target)
        assert crs.tick_until(move, timeout=30.0) == Status.SUCCESS
        positions = ctx.cache.latest("/lifter/state")[0].encoder_positions
        assert all(abs(p - target) <= ctx.config.lifter.tolerance_m for p in positions), list(positions)
        # Already there by the encoders: a second run is skipped by its guard.
        again = actuators.lifter_move("Raise", target)
        assert crs.tick_until(again, timeout=5.0) == Status.SUCCESS
        assert again.children[1].status == Status.INVALID
    finally:
        rig.close()
