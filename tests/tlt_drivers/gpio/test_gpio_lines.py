"""Named EE lines over the shared memory link and the twin's chip on it, and the GPIO
configuration files."""

from __future__ import annotations

import dataclasses

import pytest
import yaml
from tlt_sim.emulators.gpio_chip import EmulatedGpioChip

from tlt_common.config_schema import ConfigError
from tlt_drivers.gpio.config import CONFIG_DIR, load_gpio_config
from tlt_drivers.gpio.lines import open_gpio
from tlt_drivers.gpio.shared_memory import SharedGpioState, SharedMemoryLines


@pytest.fixture
def config(tmp_path):
    base = load_gpio_config(CONFIG_DIR / "gpio_x.yaml")
    return dataclasses.replace(base, emulator_state=str(tmp_path / "gpio.state"))


@pytest.mark.parametrize("arm", ["x", "y"])
def test_shipped_configs_load(arm: str) -> None:
    config = load_gpio_config(CONFIG_DIR / f"gpio_{arm}.yaml")
    names = {s.name: s.direction for s in config.lines}
    assert names == {"rivet_gun_left": "output", "rivet_gun_right": "output", "limit_switch": "input"}


def test_outputs_reach_the_twin_and_inputs_come_from_it(config) -> None:
    gpio = open_gpio(config)
    twin = EmulatedGpioChip(config.emulator_state)  # the twin's view of the same chip
    seen = []
    twin.add_output_callback(lambda line, level, edges: seen.append((line, level, edges)))
    gun = next(s for s in config.lines if s.name == "rivet_gun_left")
    switch = next(s for s in config.lines if s.name == "limit_switch")
    assert not twin.level(gun.line)
    gpio.write_output("rivet_gun_left", True)
    gpio.write_output("rivet_gun_left", False)  # a pulse between two polls
    assert twin.poll() == [(gun.line, False, 2)]
    assert seen == [(gun.line, False, 2)]
    # Pull-up, active low: released reads False; the twin pulls the line low when pressed.
    assert gpio.read_input("limit_switch") is False
    twin.set_input(switch.line, False)
    assert gpio.read_input("limit_switch") is True
    twin.set_input(switch.line, True)
    assert gpio.read_input("limit_switch") is False
    gpio.close()
    twin.close()


def test_in_process_writes_call_back_at_once(config) -> None:
    chip = EmulatedGpioChip(config.emulator_state)  # the twin hands the driver its chip
    gpio = open_gpio(config, SharedMemoryLines(chip, config.lines, owns_state=True))
    assert gpio.backend.state is chip
    fired = []
    chip.add_output_callback(lambda line, level, edges: fired.append((line, level)))
    gpio.write_output("rivet_gun_right", True)
    assert fired == [(1, True)]
    assert chip.poll() == []  # already reported
    assert gpio.read_output("rivet_gun_right") is True
    gpio.close()
    with pytest.raises(ValueError):  # the mapping is released
        chip.level(1)


def test_the_configured_backend_opens_unless_one_is_handed_in(config) -> None:
    opened = open_gpio(config)  # backend: emulator, so the shared memory file
    assert isinstance(opened.backend, SharedMemoryLines)
    assert isinstance(opened.backend.state, SharedGpioState)
    assert str(opened.backend.state.path) == config.emulator_state
    opened.close()
    chardev = dataclasses.replace(config, backend="chardev", chip=str(config.emulator_state) + ".none")
    with pytest.raises(OSError):  # the configured character device, which this machine lacks
        open_gpio(chardev)
    handed = SharedMemoryLines(SharedGpioState(), config.lines, owns_state=True)
    gpio = open_gpio(chardev, handed)  # handed in: the configuration's device is not opened
    assert gpio.backend is handed
    gpio.write_output("rivet_gun_left", True)
    assert gpio.read_output("rivet_gun_left") is True
    gpio.close()


def test_wrong_names_and_directions_are_refused(config) -> None:
    gpio = open_gpio(config)
    with pytest.raises(KeyError, match="no GPIO line named 'rivet_gun'"):
        gpio.write_output("rivet_gun", True)
    with pytest.raises(ValueError, match="'limit_switch' is an input"):
        gpio.write_output("limit_switch", True)
    with pytest.raises(ValueError, match="'rivet_gun_left' is an output"):
        gpio.read_input("rivet_gun_left")


def test_state_file_of_another_size_is_refused(tmp_path) -> None:
    EmulatedGpioChip(tmp_path / "s", num_lines=8).close()
    with pytest.raises(ValueError, match="holds 8 lines"):
        EmulatedGpioChip(tmp_path / "s", num_lines=64)


@pytest.mark.parametrize(
    "change,key",
    [
        (lambda d: d.update(backend="sysfs"), "backend"),
        (lambda d: d["lines"]["limit_switch"].update(line=0), "lines"),
        (lambda d: d["lines"]["limit_switch"].update(direction="both"), "lines.limit_switch.direction"),
        (lambda d: d["lines"]["limit_switch"].update(initial=True), "lines.limit_switch.initial"),
        (lambda d: d["lines"]["rivet_gun_left"].update(bias="strong"), "lines.rivet_gun_left.bias"),
    ],
)
def test_bad_config_names_the_key(tmp_path, change, key: str) -> None:
    doc = yaml.safe_load((CONFIG_DIR / "gpio_x.yaml").read_text())
    change(doc)
    path = tmp_path / "gpio.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as err:
        load_gpio_config(path)
    assert err.value.key == key
