"""The chain emulator as its own process: built from the driver's hardware YAML, faults from a file,
and a driver node process running against it as a launch set would start them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from tlt_sim.emulators.servo_chain_main import main

from tlt_drivers.dynamixel.chain_interface import DynamixelChainInterface
from tlt_drivers.dynamixel.config import load_chain


def start_emulator(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "tlt_sim.emulators.servo_chain_main", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    line = proc.stdout.readline().strip()
    assert line.startswith("/dev/"), proc.stderr.read()
    return proc, line


def stop(proc: subprocess.Popen) -> int:
    proc.send_signal(signal.SIGTERM)
    return proc.wait(timeout=10)


def test_faults_file_makes_a_servo_silent_and_link_is_removed_on_exit(tmp_path):
    faults = tmp_path / "faults.yaml"
    faults.write_text("silent_ids: [3]\n")
    link = tmp_path / "ttyAG"
    proc, _ = start_emulator(
        "--hardware", "config/hardware/active_grippers.yaml", "--link", str(link), "--faults", str(faults)
    )
    try:
        config = load_chain("config/hardware/active_grippers.yaml")
        config["port"] = str(link)
        config["comm"]["latency_timer_ms"] = 60.0
        hw = DynamixelChainInterface(config)
        assert not hw.configure()
        assert "'active_gripper_3' (id 3)" in hw.fault
        hw.shutdown()
    finally:
        assert stop(proc) == 0
    assert not link.exists()


def test_bad_faults_file_is_a_clear_error(tmp_path, capsys):
    faults = tmp_path / "faults.yaml"
    faults.write_text("silent_ids: [9]\n")
    assert main(["--hardware", "config/hardware/active_grippers.yaml", "--faults", str(faults)]) == 2
    assert "silent_ids: id 9 is not on this chain" in capsys.readouterr().err


def test_not_a_chain_file_is_refused(tmp_path, capsys):
    other = tmp_path / "x.yaml"
    other.write_text("component: lifter\n")
    assert main(["--hardware", str(other)]) == 2
    assert "not a servo chain" in capsys.readouterr().err


@pytest.mark.timeout(60)
def test_top_grippers_node_process_runs_against_the_emulator_process(tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from tlt_interfaces.msg import GripperState

    link = tmp_path / "ttyTG"
    emulator, _ = start_emulator("--hardware", "config/hardware/top_grippers.yaml", "--link", str(link))
    driver = subprocess.Popen(
        [sys.executable, "-m", "tlt_drivers.nodes.top_grippers", "--port", str(link)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ),
    )
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("top_grippers_probe", context=context)
    states: list[GripperState] = []
    node.create_subscription(GripperState, "/top_grippers/state", states.append, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and not (states and states[-1].torque_enabled):
            executor.spin_once(timeout_sec=0.1)
        assert states and states[-1].torque_enabled and not states[-1].fault, driver.stderr
        assert list(states[-1].joint_names) == [f"top_gripper_{i}" for i in (1, 2, 3, 4)]
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
        assert stop(driver) == 0
        assert stop(emulator) == 0
