"""The bring-up check says which driver did not come up, after its start-up allowance, and exits
non-zero: here no driver runs at all."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

CHECK = Path(sys.executable).with_name("tlt-bringup-check")


def test_a_driver_that_never_comes_up_fails_after_the_startup_allowance():
    started = time.monotonic()
    result = subprocess.run(
        [str(CHECK), "--components", "lifter", "--timeout", "1", "--startup-timeout", "3"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    took = time.monotonic() - started
    assert result.returncode == 1, result.stdout + result.stderr
    assert (
        "FAIL lifter           driver up                          hardware interface active with "
        "its link up: not seen on /lifter/hardware_status within 3 s"
    ) in result.stdout, result.stdout
    # The lifter's later checks are not tried without its driver.
    assert "bring-up check: 0 of 1 checks passed" in result.stdout, result.stdout
    assert took >= 3.0
