"""The EE node's GPIO comes from the GPIO driver (tlt_drivers.gpio) as its map file says."""

from __future__ import annotations

from pathlib import Path

import pytest
from tlt_sim.emulators.gpio_chip import EmulatedGpioChip

from tlt_drivers.dynamixel.config import load_chain
from tlt_drivers.nodes.ee import GpioUnavailable, open_ee_gpio


def test_ee_gpio_map_opens_emulated_lines(tmp_path):
    state = tmp_path / "gpio.state"
    gpio_map = tmp_path / "gpio_x.yaml"
    gpio_map.write_text(
        "component: gpio_x\nbackend: emulator\n"
        f"emulator_state: {state}\n"
        "lines:\n"
        "  rivet_gun_left: {line: 0, direction: output}\n"
        "  rivet_gun_right: {line: 1, direction: output}\n"
        "  limit_switch: {line: 2, direction: input, active_low: true, bias: pull_up}\n"
    )
    config = load_chain("config/hardware/ee_x.yaml")
    config["ee"]["gpio_config"] = str(gpio_map)
    lines = open_ee_gpio(config)
    twin = EmulatedGpioChip(state)
    try:
        twin.drive(2, True)  # switch open: the pulled-up line reads high, logically inactive
        assert lines.read_input(config["ee"]["limit_switch_input"]) is False
        twin.drive(2, False)  # pressed: active low
        assert lines.read_input(config["ee"]["limit_switch_input"]) is True
        lines.write_output(config["ee"]["rivet_gun_outputs"][0], True)
        assert twin.level(0) is True and twin.level(1) is False
    finally:
        lines.close()
        twin.close()


def test_shipped_ee_configs_name_lines_of_their_gpio_maps():
    from tlt_drivers.gpio.config import CONFIG_DIR, load_gpio_config

    for axis in ("x", "y"):
        ee = load_chain(f"config/hardware/ee_{axis}.yaml")["ee"]
        names = {spec.name: spec.direction for spec in load_gpio_config(CONFIG_DIR / ee["gpio_config"]).lines}
        assert names[ee["limit_switch_input"]] == "input"
        assert all(names[out] == "output" for out in ee["rivet_gun_outputs"])


def test_missing_gpio_map_is_a_clear_error():
    config = load_chain("config/hardware/ee_x.yaml")
    config["ee"]["gpio_config"] = None
    with pytest.raises(GpioUnavailable, match="names no GPIO map"):
        open_ee_gpio(config)


@pytest.mark.timeout(60)
def test_ee_x_process_with_emulated_chain_and_gpio(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    import rclpy
    import yaml
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from tlt_interfaces.msg import EndEffectorState

    gpio_map = tmp_path / "gpio_x.yaml"
    gpio_map.write_text(
        f"component: gpio_x\nbackend: emulator\nemulator_state: {tmp_path / 'gpio.state'}\nlines:\n"
        "  rivet_gun_left: {line: 0, direction: output}\n"
        "  rivet_gun_right: {line: 1, direction: output}\n"
        "  limit_switch: {line: 2, direction: input, active_low: true, bias: pull_up}\n"
    )
    doc = yaml.safe_load(Path("config/hardware/ee_x.yaml").read_text())
    doc["ee"]["gpio_config"] = str(gpio_map)
    ee_yaml = tmp_path / "ee_x.yaml"
    ee_yaml.write_text(yaml.safe_dump(doc))
    link = tmp_path / "ttyEE"
    emulator = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tlt_sim.emulators.servo_chain_main",
            "--hardware",
            str(ee_yaml),
            "--link",
            str(link),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert emulator.stdout.readline().startswith("/dev/")
    driver = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from tlt_drivers.nodes.ee import main_x; sys.exit(main_x(sys.argv[1:]))",
            "--config",
            str(ee_yaml),
            "--port",
            str(link),
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("ee_probe", context=context)
    states: list[EndEffectorState] = []
    node.create_subscription(EndEffectorState, "/ee_x/state", states.append, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 30.0
        # The emulated chain's width carriage presses the limit switch on the shared GPIO chip.
        while time.monotonic() < deadline and not (states and states[-1].calibrated):
            executor.spin_once(timeout_sec=0.1)
        assert states and not states[-1].fault, "no healthy EndEffectorState from the ee_x process"
        assert states[-1].ars == "ars_x"
        assert states[-1].calibrated and states[-1].limit_switch
        assert list(states[-1].rivet_gun_output) == [False, False]
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
        driver.send_signal(signal.SIGTERM)
        assert driver.wait(timeout=10) == 0, driver.stderr.read()
        emulator.send_signal(signal.SIGTERM)
        assert emulator.wait(timeout=10) == 0
