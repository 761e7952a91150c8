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


def test_debian_packages_that_cannot_be_installed_are_named_and_set_up_goes_on(tmp_path):
    """Without apt-get (another distribution, a container without it) set-up says which packages
    are missing and why, then carries on with the next stage (here: a venv stage that fails on a
    wrong interpreter, which shows the apt stage did not stop it)."""
    (tmp_path / "scripts").mkdir()
    (tmp_path / "scripts" / "setup.sh").write_text(SETUP.read_text())
    (tmp_path / "requirements").mkdir()
    (tmp_path / "requirements" / "apt.txt").write_text("# test\nbash\ntlt-no-such-package  # none\n")
    no_apt = tmp_path / "bin"
    no_apt.mkdir()
    for folder in ("/usr/local/bin", "/usr/bin", "/bin"):
        for tool in Path(folder).iterdir():
            link = no_apt / tool.name
            if not tool.name.startswith("apt") and not link.exists():
                link.symlink_to(tool)
    env = {
        **os.environ,
        "PATH": str(no_apt),
        "TLT_VENV": str(tmp_path / "venv"),
        "TLT_PYTHON": "python3.10",
    }
    result = subprocess.run(
        ["bash", str(tmp_path / "scripts" / "setup.sh")], capture_output=True, text=True, timeout=120, env=env
    )
    assert (
        "[setup] WARNING: Debian packages NOT installed (apt-get is not available on this system): "
        "tlt-no-such-package" in result.stderr
    ), result.stderr
    assert "python3.10" in result.stderr.split("WARNING")[-1], "the next stage ran"
