"""scripts/device_train.sh refuses what it cannot do before it touches the machine: an unknown
step, and a device step without what `prepare` fetches (the device reaches no network)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "device_train.sh"


def _run(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", str(SCRIPT), *args], capture_output=True, text=True, timeout=60, env={**os.environ, **env}
    )


def test_an_unknown_step_is_refused_with_the_usage():
    result = _run("render")
    assert result.returncode == 2
    assert "usage:" in result.stderr and "prepare|train|candidate" in result.stderr


def test_train_without_prepare_says_to_run_it_and_installs_nothing(tmp_path):
    result = _run("train", DEVICE_DIR=str(tmp_path / "none"), OUT=str(tmp_path / "out"))
    assert result.returncode == 2
    assert "prepare" in result.stderr and "carry .device" in result.stderr
    assert not (tmp_path / "out").exists()
