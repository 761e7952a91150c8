"""The EE GPIO map (``config/hardware/gpio_x.yaml``, ``gpio_y.yaml``), validated on load."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from tlt_common.config_schema import ConfigError, Field, load_validated, opt

from .uapi import LINES_MAX

CONFIG_DIR = Path(__file__).resolve().parents[3] / "config" / "hardware"
DEFAULT_CONFIG = CONFIG_DIR / "gpio_x.yaml"

LINE_SCHEMA = {
    "line": Field("int", minimum=0, maximum=1023, doc="line offset on the GPIO chip"),
    "direction": Field("str", choices=("input", "output")),
    "active_low": opt("bool", False, doc="the logical level is the inverse of the electrical one"),
    "bias": opt("str", "as_is", choices=("as_is", "pull_up", "pull_down", "disabled")),
    "initial": opt("bool", False, doc="level an output takes when the line is requested"),
}


def _check_lines(lines: dict) -> str | None:
    if not lines:
        return "at least one line is needed"
    if len(lines) > LINES_MAX:
        return f"at most {LINES_MAX} lines"
    offsets = [spec["line"] for spec in lines.values()]
    if len(set(offsets)) != len(offsets):
        return f"two names map to the same line: {sorted(offsets)}"
    return None


GPIO_SCHEMA = {
    "component": Field("str", doc="name of this GPIO set, e.g. gpio_x"),
    "backend": Field(
        "str", choices=("chardev", "emulator"), doc="chardev on the Jetson, emulator with the twin"
    ),
    "chip": opt("str", "/dev/gpiochip0", doc="GPIO character device (chardev backend)"),
    "consumer": opt("str", "tlt", doc="consumer label shown by gpioinfo"),
    "emulator_state": opt(
        "str", "gpio.state", doc="shared state file (emulator backend); relative to $TLT_RUN_DIR"
    ),
    "lines": Field("map", item=Field("dict", schema=LINE_SCHEMA), check=_check_lines),
}


@dataclass(frozen=True)
class LineSpec:
    name: str
    line: int
    direction: str
    active_low: bool = False
    bias: str = "as_is"
    initial: bool = False


@dataclass(frozen=True)
class GpioConfig:
    component: str
    backend: str
    lines: tuple[LineSpec, ...]
    chip: str = "/dev/gpiochip0"
    consumer: str = "tlt"
    emulator_state: str = "gpio.state"


def load_gpio_config(path: str | Path = DEFAULT_CONFIG) -> GpioConfig:
    """Load and validate a GPIO map; ``ConfigError`` names the file, key and reason."""
    doc = load_validated(path, GPIO_SCHEMA)
    lines = tuple(LineSpec(name=name, **spec) for name, spec in doc.pop("lines").items())
    for spec in lines:
        if spec.direction == "input" and spec.initial:
            raise ConfigError(path, f"lines.{spec.name}.initial", "only outputs have an initial level")
    # The emulated chip's state lives with the run's other device links, so runs side by side
    # (a test session beside a main job) each have their own.
    doc["emulator_state"] = str(run_dir() / doc["emulator_state"])
    return GpioConfig(lines=lines, **doc)


def run_dir() -> Path:
    """Where this run's emulated device links live: $TLT_RUN_DIR, by default /tmp/tlt-run."""
    return Path(os.environ.get("TLT_RUN_DIR") or "/tmp/tlt-run")


__all__ = ["CONFIG_DIR", "DEFAULT_CONFIG", "GPIO_SCHEMA", "GpioConfig", "LineSpec", "load_gpio_config"]
