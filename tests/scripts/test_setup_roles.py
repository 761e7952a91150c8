"""scripts/setup.sh --role: each role installs its own requirement files (the ground role none of
the ROS, torch or MuJoCo wheels), every pin lives in one file, and the dev role, the default,
installs them all. Nothing here installs anything."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SETUP = ROOT / "scripts" / "setup.sh"
REQUIREMENTS = ROOT / "requirements"
# The files that are not pip requirement files: Debian packages, and the aarch64 routes.
NOT_PIP = {"apt.txt", "aarch64.txt"}

EXPECTED_FILES = {
    "ground": ["base.txt", "ground.txt"],
    "robot": ["base.txt", "ros.txt", "robot.txt"],
    "vision": ["base.txt", "ros.txt", "images.txt", "vision.txt"],
    "twin": ["base.txt", "ros.txt", "images.txt", "twin.txt"],
    "dev": ["runtime.txt", "dev.txt"],
}
# Per role: distributions it must install, and ones it must not pull in.
MUST = {
    "ground": {"pyside6-essentials", "pyqtgraph", "spacepackets", "py-trees", "matplotlib", "setuptools"},
    "robot": {"ros-jazzy-rclpy", "ur-rtde", "dynamixel-sdk", "pyserial", "ompl", "pin", "coal", "mcap"},
    "vision": {"ros-jazzy-rclpy", "torch", "opencv-contrib-python-headless", "scipy"},
    "twin": {"ros-jazzy-rclpy", "mujoco", "opencv-contrib-python-headless", "scipy"},
    "dev": {"ros-jazzy-rclpy", "torch", "mujoco", "pyside6-essentials", "pytest", "ruff"},
}
MUST_NOT = {
    "ground": {"torch", "mujoco", "scipy", "opencv-contrib-python-headless", "ompl", "pin", "ur-rtde"},
    "robot": {"torch", "mujoco", "pyside6-essentials", "opencv-contrib-python-headless", "pytest"},
    "vision": {"mujoco", "pyside6-essentials", "ur-rtde", "ompl", "pytest"},
    "twin": {"torch", "pyside6-essentials", "ur-rtde", "ompl", "pytest"},
    "dev": set(),
}


def _name(line: str) -> str:
    return re.sub(r"[-_.]+", "-", re.split(r"[\[=<>!~;@ ]", line, maxsplit=1)[0]).lower()


def _pins(path: Path) -> list[str]:
    """The requirement lines of a file and of those it includes (-r)."""
    lines: list[str] = []
    for raw in path.read_text().splitlines():
        line = raw.split("#", 1)[0].strip()
        if line.startswith("-r"):
            lines += _pins(path.parent / line[2:].strip())
        elif line:
            lines.append(line)
    return lines


def _setup(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", str(SETUP), *args], capture_output=True, text=True, timeout=60, env=env or dict(os.environ)
    )


@pytest.mark.parametrize("role", sorted(EXPECTED_FILES))
def test_a_role_names_its_requirement_files(role):
    result = _setup("--role", role, "--print-requirements")
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [f"requirements/{f}" for f in EXPECTED_FILES[role]]
    names = {_name(line) for f in result.stdout.split() for line in _pins(ROOT / f)}
    assert MUST[role] <= names, MUST[role] - names
    assert not names & MUST_NOT[role], names & MUST_NOT[role]
    if role == "ground":
        assert not {n for n in names if n.startswith("ros-")}, "the GSW runs no ROS node"


def test_the_default_role_is_dev_and_the_environment_can_name_one():
    assert _setup("--print-requirements").stdout == _setup("--role", "dev", "--print-requirements").stdout
    env = {**os.environ, "TLT_ROLE": "ground"}
    assert _setup("--print-requirements", env=env).stdout.split() == [
        "requirements/base.txt",
        "requirements/ground.txt",
    ]


def test_dev_installs_every_pin_and_each_pin_lives_in_one_file():
    files = sorted(p for p in REQUIREMENTS.glob("*.txt") if p.name not in NOT_PIP)
    owners: dict[str, list[str]] = {}
    for path in files:
        for raw in path.read_text().splitlines():
            line = raw.split("#", 1)[0].strip()
            if line and not line.startswith("-r"):
                owners.setdefault(_name(line), []).append(path.name)
    assert {n: f for n, f in owners.items() if len(f) > 1} == {}
    dev = {_name(line) for f in EXPECTED_FILES["dev"] for line in _pins(REQUIREMENTS / f)}
    assert dev == set(owners)
    # Every role's files are among those the dev role installs.
    included = {f for files_ in EXPECTED_FILES.values() for f in files_}
    assert {p.name for p in files} == included


def test_an_unknown_role_is_refused_before_anything_is_made(tmp_path):
    env = {**os.environ, "TLT_VENV": str(tmp_path / "venv")}
    result = _setup("--role", "jetson", env=env)
    assert result.returncode != 0
    assert "[setup] FAILED: unknown role jetson (ground, robot, vision, twin or dev)" in result.stderr
    assert not (tmp_path / "venv").exists()


def _without_apt(tmp_path: Path) -> Path:
    no_apt = tmp_path / "bin"
    no_apt.mkdir()
    for folder in ("/usr/local/bin", "/usr/bin", "/bin"):
        for tool in Path(folder).iterdir():
            link = no_apt / tool.name
            if not tool.name.startswith("apt") and not link.exists():
                link.symlink_to(tool)
    return no_apt


@pytest.mark.parametrize(
    ("role", "wanted"),
    [
        ("ground", "tlt-no-such-every tlt-no-such-ground-twin"),
        ("twin", "tlt-no-such-every tlt-no-such-twin tlt-no-such-ground-twin"),
        ("dev", "tlt-no-such-every tlt-no-such-twin tlt-no-such-ground-twin tlt-no-such-dev"),
    ],
)
def test_a_role_asks_for_the_debian_packages_of_its_lines(tmp_path, role, wanted):
    """A line of requirements/apt.txt names the roles that need its package (none: every role;
    dev takes every line). Without apt-get, set-up names the role's missing packages and goes on
    to the venv stage, which fails here on a wrong interpreter."""
    (tmp_path / "scripts").mkdir()
    (tmp_path / "scripts" / "setup.sh").write_text(SETUP.read_text())
    (tmp_path / "requirements").mkdir()
    (tmp_path / "requirements" / "apt.txt").write_text(
        "# test\nbash\ntlt-no-such-every\ntlt-no-such-twin  twin  # twin only\n"
        "tlt-no-such-ground-twin ground twin\ntlt-no-such-dev dev\n"
    )
    env = {
        **os.environ,
        "PATH": str(_without_apt(tmp_path)),
        "TLT_VENV": str(tmp_path / "venv"),
        "TLT_PYTHON": "python3.10",
    }
    result = subprocess.run(
        ["bash", str(tmp_path / "scripts" / "setup.sh"), "--role", role],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    warning = "[setup] WARNING: Debian packages NOT installed (apt-get is not available on this system)"
    assert f"{warning}: {wanted}\n" in result.stderr, result.stderr
    assert "python3.10" in result.stderr.split("WARNING")[-1], "the next stage ran"
