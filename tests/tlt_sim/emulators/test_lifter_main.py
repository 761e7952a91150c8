"""The lifter firmware emulator as a standalone process: prints its pty, makes the symlink the
driver's port names, answers the real driver, and cleans up on SIGTERM."""

from __future__ import annotations

import signal
import subprocess
import sys

from tlt_sim.emulators.lifter_main import main

from tlt_drivers.hardware_interface import Lifecycle
from tlt_drivers.lifter.config import load_lifter_config
from tlt_drivers.lifter.serial_interface import LifterSerialInterface


def test_emulator_process_serves_the_driver_and_cleans_up(tmp_path) -> None:
    link = tmp_path / "lifter"
    proc = subprocess.Popen(
        [sys.executable, "-m", "tlt_sim.emulators.lifter_main", "--link", str(link)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        printed = proc.stdout.readline().strip()
        assert printed == str(link) and link.is_symlink()
        hw = LifterSerialInterface(load_lifter_config().with_port(printed))
        assert hw.configure(), hw.fault
        assert hw.state == Lifecycle.INACTIVE and hw.telemetry is not None
        hw.shutdown()
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()  # never leave an emulator behind, even when it hangs
            proc.wait()
            raise
    assert code == 0
    assert not link.exists() and not link.is_symlink()


def test_bad_config_is_refused_naming_the_key(tmp_path, capsys) -> None:
    bad = tmp_path / "fw.yaml"
    bad.write_text("command_period_s: 0.02\nlower_limit_counts: [0, 0]\nupper_limit_counts: [1, 1, 1, 1]\n")
    assert main(["--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "fw.yaml: lower_limit_counts" in err and "expected 4 values" in err
