"""The emulated UR controller's configuration: where it serves, what it reports (version, serial
number), its initial joints and the faults present from the start, loaded from
``config/sim/ur_x_controller.yaml`` / ``ur_y_controller.yaml``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from tlt_common.config_schema import Field, load_validated, opt
from tlt_sim.emulators.ur_arm import HOME


@dataclass
class URControllerConfig:
    """Where and what the emulated controller is."""

    host: str = "127.0.0.1"
    dashboard_port: int = 29999
    rtde_port: int = 30004
    script_port: int = 30003
    version: tuple[int, int, int, int] = (5, 11, 0, 108249)
    serial_number: str = "20235500001"
    remote_control: bool = True
    unlock_delay_s: float = 5.0  # the controller refuses an unlock this soon after the stop
    tick_hz: float = 500.0
    clock: str = "internal"  # "internal": wall time steps the arm; "external": advance(dt) does
    q0: Sequence[float] = field(default_factory=lambda: list(HOME))
    # Faults present from the start (tests inject more through the emulator's methods).
    fault_no_answer: bool = False
    fault_protective_stop: bool = False
    fault_link_down: bool = False


CONFIG_DIR = Path(__file__).resolve().parents[3] / "config" / "sim"


def _six(values: list) -> str | None:
    return None if len(values) == 6 else f"expected 6 joint values, got {len(values)}"


CONFIG_SCHEMA = {
    "host": Field("str", doc="loopback address of this arm's controller"),
    "version": opt(
        "list",
        [5, 11, 0, 108249],
        item=Field("int", minimum=0),
        check=lambda v: None if len(v) == 4 else "expected [major, minor, bugfix, build]",
    ),
    "serial_number": opt("str", "20235500001"),
    "remote_control": opt("bool", True),
    "unlock_delay_s": opt("float", 5.0, minimum=0.0),
    "tick_hz": opt("float", 500.0, minimum=10.0, maximum=1000.0),
    "clock": opt("str", "internal", choices=("internal", "external")),
    "q0": opt("list", list(HOME), item=Field("float"), check=_six),
    "faults": opt(
        "dict",
        {"no_answer": False, "protective_stop": False, "link_down": False},
        schema={
            "no_answer": opt("bool", False),
            "protective_stop": opt("bool", False),
            "link_down": opt("bool", False),
        },
    ),
}


def load_controller_config(path: str | Path) -> URControllerConfig:
    """Load ``config/sim/ur_<arm>_controller.yaml``; ``ConfigError`` names file, key and reason."""
    doc = load_validated(path, CONFIG_SCHEMA)
    faults = doc.pop("faults")
    return URControllerConfig(
        **{k: v for k, v in doc.items() if k != "version"},
        version=tuple(doc["version"][:4]),
        fault_no_answer=faults["no_answer"],
        fault_protective_stop=faults["protective_stop"],
        fault_link_down=faults["link_down"],
    )


__all__ = ["CONFIG_DIR", "CONFIG_SCHEMA", "URControllerConfig", "load_controller_config"]
