"""Run the lifter firmware emulator as its own process, for launch sets and benchmarks.

Opens a pseudo-terminal, prints its path on stdout (one line, flushed) and, with ``--link`` or the
config's ``link_path``, makes a symlink to it that the driver's ``port`` names. Runs until SIGINT
or SIGTERM, then closes the pty and removes the symlink.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from tlt_common.config_schema import ConfigError

from .lifter_firmware import FirmwareFaults, LifterFirmware, load_firmware_config
from .lifter_pty import PtyFirmwareServer

DEFAULT_CONFIG = Path(__file__).resolve().parents[3] / "config" / "sim" / "lifter_firmware.yaml"


def main(argv: list[str] | None = None) -> int:
    """Serve the emulator until a signal arrives. Returns the exit status (2 on a bad config)."""
    parser = argparse.ArgumentParser(prog="tlt-lifter-emulator", description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="firmware emulator YAML")
    parser.add_argument("--link", help="symlink to create to the pty (overrides the config's link_path)")
    args = parser.parse_args(argv)
    try:
        config, doc = load_firmware_config(args.config)
        stuck = {}
        for key, pressed in doc["faults"]["stuck_switches"].items():
            if not key.isdigit() or not 0 <= int(key) < 8:
                raise ConfigError(args.config, f"faults.stuck_switches.{key}", "expected a switch index 0..7")
            stuck[int(key)] = pressed
    except ConfigError as exc:
        print(f"tlt-lifter-emulator: {exc}", file=sys.stderr)
        return 2
    faults = FirmwareFaults(
        no_answer=doc["faults"]["no_answer"], corrupt_every_n=doc["faults"]["corrupt_every_n"]
    )
    firmware = LifterFirmware(config, faults)
    for index, pressed in stuck.items():
        firmware.force_switch(index, pressed)
    link = args.link if args.link is not None else doc["link_path"]
    server = PtyFirmwareServer(firmware, link_path=link or None)
    # The handler only appends to a list: taking a lock in a signal handler (Event.set) deadlocks
    # when the signal lands while the main thread holds that same lock inside Event.wait.
    stop_signals: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: stop_signals.append(signum))
    path = server.start()
    print(path, flush=True)
    try:
        while not stop_signals:
            time.sleep(0.1)
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
