"""The ``lifter`` driver as its own process (as a launch set starts it), against the emulator:
it publishes LifterState, serves SetLifterMode, and stops cleanly on SIGINT."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from tlt_interfaces.msg import LifterState
from tlt_interfaces.srv import SetLifterMode
from tlt_sim.emulators.lifter_firmware import FirmwareConfig, LifterFirmware
from tlt_sim.emulators.lifter_pty import PtyFirmwareServer

from tlt_drivers.lifter.config import DEFAULT_CONFIG
from tlt_drivers.lifter.protocol import FirmwareState

TIMEOUT_S = 30.0


def test_driver_process_publishes_serves_and_stops(tmp_path) -> None:
    firmware = LifterFirmware(FirmwareConfig(init_duration_s=0.05))
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("lifter_process_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    states: list[LifterState] = []
    node.create_subscription(LifterState, "lifter/state", states.append, 10)
    client = node.create_client(SetLifterMode, "lifter/set_mode")
    # the shipped config, with the link timeout widened for a loaded test machine
    config = tmp_path / "lifter.yaml"
    text = DEFAULT_CONFIG.read_text()
    assert "link_timeout_s: 0.2\n" in text
    config.write_text(text.replace("link_timeout_s: 0.2\n", "link_timeout_s: 1.0\n"))
    with PtyFirmwareServer(firmware, link_path=tmp_path / "lifter") as server:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "tlt_drivers.lifter.node",
                "--config",
                str(config),
                "--port",
                str(server.link_path),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            deadline = time.monotonic() + TIMEOUT_S
            while time.monotonic() < deadline and not (
                states and states[-1].link_ok and states[-1].state == LifterState.STATE_HARDWARE_CONTROL
            ):
                executor.spin_once(timeout_sec=0.05)
                assert proc.poll() is None, proc.stdout.read()
            assert states and states[-1].link_ok, "no healthy LifterState from the driver process"
            assert client.wait_for_service(timeout_sec=TIMEOUT_S)
            future = client.call_async(SetLifterMode.Request(mode=SetLifterMode.Request.MODE_SAFE))
            executor.spin_until_future_complete(future, timeout_sec=TIMEOUT_S)
            assert future.done() and future.result().success
            assert firmware.state == FirmwareState.SAFE
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                code = proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                raise
            output = proc.stdout.read()
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
        assert code == 0, output


def test_an_answer_or_link_timeout_out_of_range_is_refused_before_anything_starts(capsys):
    from tlt_drivers.lifter.node import main

    assert main(["--answer-timeout-s", "0"]) == 2
    assert "--answer-timeout-s must be in (0, 10] s" in capsys.readouterr().err
    assert main(["--link-timeout-s", "11"]) == 2
    assert "--link-timeout-s must be in (0, 10] s" in capsys.readouterr().err
