"""scripts/setup.sh: a second run finds everything in place and changes nothing; a failure says
what failed and leaves nothing a later run would trust."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SETUP = ROOT / "scripts" / "setup.sh"


def _snapshot(venv: Path) -> dict[str, float]:
    watched = [venv / ".tlt-stamps", venv / "lib" / "python3.11" / "site-packages", venv / "bin"]
    return {str(p): p.stat().st_mtime_ns for d in watched for p in [d, *d.iterdir()]}


def test_a_second_run_changes_nothing():
    venv = Path(os.environ.get("TLT_VENV", ROOT / ".venv"))
    before = _snapshot(venv)
    result = subprocess.run(["bash", str(SETUP)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [f"[setup] ready: {venv}"]
    assert _snapshot(venv) == before


def test_a_failed_stage_is_named_and_not_trusted(tmp_path):
    venv = tmp_path / "venv"
    env = {**os.environ, "TLT_VENV": str(venv), "TLT_PYTHON": "python3.10"}
    result = subprocess.run(["bash", str(SETUP)], capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode != 0
    assert (
        "[setup] FAILED: python3.10 is not Python 3.11" in result.stderr
        or "[setup] FAILED: python3.10 not found" in result.stderr
    )
    assert not (venv / ".tlt-stamps").exists()
