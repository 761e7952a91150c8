"""Run an emulated Dynamixel or MightyZAP chain as its own process, for launch sets and benchmarks.

The chain is built from the driver's own hardware YAML (``config/hardware/*.yaml``): a file with
``joints`` gives MX-106(2.0) servos with those ids, one with ``actuators`` gives MightyZAPs. The
process opens a pseudo-terminal, prints its path on stdout (one line, flushed) and, with
``--link``, makes a symlink to it for the driver's ``--port``. ``--faults`` names a YAML of faults
to inject from the start::

    silent_ids: [3]          # these ids never answer
    dropped: false           # nothing answers (a pulled cable)
    corrupt_replies: 0       # the first N replies carry a wrong CRC / checksum
    hardware_errors: {"2": 32}  # latched error bits per id (Dynamixel: Hardware Error Status)

Runs until SIGINT or SIGTERM, then closes the pty and removes the symlink.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate
from tlt_sim.emulators.dynamixel_chain import DynamixelChain
from tlt_sim.emulators.ee_limit_switch import WidthLimitSwitch
from tlt_sim.emulators.gpio_chip import EmulatedGpioChip
from tlt_sim.emulators.mightyzap_chain import MightyZapChain
from tlt_sim.emulators.pty_device import publish_link, withdraw_link

FAULTS_SCHEMA = {
    "silent_ids": opt("list", [], item=Field("int", minimum=0, maximum=253)),
    "dropped": opt("bool", False),
    "corrupt_replies": opt("int", 0, minimum=0),
    "hardware_errors": opt("map", {}, item=Field("int", minimum=0, maximum=255)),
}


def build_chain(hardware: Any, source: str | Path) -> DynamixelChain | MightyZapChain:
    """The emulated chain for a driver's hardware YAML (already parsed)."""
    if not isinstance(hardware, dict):
        raise ConfigError(source, "", "expected a mapping")
    if "joints" in hardware:
        from tlt_drivers.dynamixel.config import validate_chain

        cfg = validate_chain(hardware, source)
        return DynamixelChain([j["id"] for j in cfg["joints"]])
    if "actuators" in hardware:
        from tlt_drivers.mightyzap.config import validate_mightyzap

        cfg = validate_mightyzap(hardware, source)
        return MightyZapChain([a["id"] for a in cfg["actuators"]])
    raise ConfigError(
        source, "", "neither 'joints' (Dynamixel) nor 'actuators' (MightyZAP): not a servo chain"
    )


def apply_faults(chain: DynamixelChain | MightyZapChain, faults: dict[str, Any], source: str | Path) -> None:
    """Inject the validated ``faults`` into ``chain``; unknown ids are a ConfigError."""
    known = set(chain.servos if isinstance(chain, DynamixelChain) else chain.actuators)
    for dxl_id in faults["silent_ids"]:
        if dxl_id not in known:
            raise ConfigError(source, "silent_ids", f"id {dxl_id} is not on this chain {sorted(known)}")
        chain.silence(dxl_id)
    chain.drop_link(faults["dropped"])
    chain.corrupt_next(faults["corrupt_replies"])
    for key, bits in faults["hardware_errors"].items():
        if not key.isdigit() or int(key) not in known:
            raise ConfigError(source, f"hardware_errors.{key}", f"not an id on this chain {sorted(known)}")
        if isinstance(chain, DynamixelChain):
            chain.servo(int(key)).inject_hardware_error(bits)
        else:
            chain.actuator(int(key)).error |= bits


def ee_limit_switch(hardware: dict[str, Any], chain: DynamixelChain, source: str | Path) -> WidthLimitSwitch:
    """For an end-effector chain: its calibration limit switch on the GPIO map's emulated chip."""
    from tlt_drivers.dynamixel.config import validate_chain
    from tlt_drivers.gpio.config import CONFIG_DIR, load_gpio_config

    cfg = validate_chain(hardware, source)
    ee = cfg["ee"]
    # Relative GPIO maps live beside the hardware configs, as the EE node reads them.
    gpio = load_gpio_config(CONFIG_DIR / ee["gpio_config"])
    if gpio.backend != "emulator":
        raise ConfigError(
            source,
            "ee.gpio_config",
            f"{gpio.component} uses the {gpio.backend} backend, "
            "not the emulator: nothing to drive the limit switch",
        )
    switch = next(spec for spec in gpio.lines if spec.name == ee["limit_switch_input"])
    width = next(j for j in cfg["joints"] if j["name"] == ee["width_joint"])
    direction = ee["calibration"]["direction"] * width["direction"]
    return WidthLimitSwitch(
        chain.servo(width["id"]),
        EmulatedGpioChip(gpio.emulator_state),
        switch.line,
        active_low=switch.active_low,
        lead_m_per_rev=width["lead_m_per_rev"],
        direction=direction,
    )


def main(argv: list[str] | None = None) -> int:
    """Serve the chain until a signal arrives. Returns the exit status (2 on a bad config)."""
    parser = argparse.ArgumentParser(prog="tlt-servo-chain-emulator", description=__doc__.splitlines()[0])
    parser.add_argument("--hardware", type=Path, required=True, help="the driver's hardware YAML")
    parser.add_argument("--link", type=Path, help="symlink to create to the pty")
    parser.add_argument("--faults", type=Path, help="YAML of faults to inject")
    args = parser.parse_args(argv)
    try:
        hardware = load_yaml(args.hardware)
        chain = build_chain(hardware, args.hardware)
        switch = ee_limit_switch(hardware, chain, args.hardware) if "ee" in hardware else None
        if args.faults is not None:
            apply_faults(
                chain, validate(load_yaml(args.faults), FAULTS_SCHEMA, source=args.faults), args.faults
            )
    except ConfigError as exc:
        print(f"tlt-servo-chain-emulator: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    path = chain.start()
    if args.link is not None:
        publish_link(args.link, path)
    print(path, flush=True)
    try:
        # An end effector's limit switch follows the width carriage between packets too.
        while not stop.wait(0.01 if switch else 0.5):
            if switch:
                chain.catch_up()
                switch.update()
    finally:
        chain.stop()
        if args.link is not None:
            withdraw_link(args.link, path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
