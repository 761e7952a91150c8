"""SIGINT and SIGTERM become a stop request the process reads, not an exit or a KeyboardInterrupt."""

from __future__ import annotations

import subprocess
import sys

PROGRAM = """
import os, signal
from tlt_common.ros.stop_signals import stop_on_signals
stop = stop_on_signals()
os.kill(os.getpid(), signal.SIGTERM)
os.kill(os.getpid(), signal.SIGINT)
print(stop == [signal.SIGTERM, signal.SIGINT], flush=True)
"""


def test_signals_are_collected_and_the_process_goes_on():
    result = subprocess.run([sys.executable, "-c", PROGRAM], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "True"
