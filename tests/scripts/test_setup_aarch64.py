"""scripts/setup_aarch64.sh check: every pin of the Jetsons' roles (robot, vision) is an aarch64
wheel for CPython 3.11 or has a route in requirements/aarch64.txt, and a pin with neither fails
the check. The tests marked ``network`` ask the package registry (a resolver dry run)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHECK = ROOT / "scripts" / "setup_aarch64.sh"
ROUTES = ROOT / "requirements" / "aarch64.txt"


def _check(*args: str) -> subprocess.CompletedProcess[str]:
    # The venv's interpreter runs pip; the target (aarch64, CPython 3.11) is given to pip.
    env = {**os.environ, "TLT_PYTHON": sys.executable}
    return subprocess.run(
        ["bash", str(CHECK), "check", *args], capture_output=True, text=True, timeout=540, env=env
    )


@pytest.mark.network
def test_the_jetsons_roles_have_an_aarch64_route_for_every_pin():
    result = _check()
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "[aarch64] ok: " in out
    for wheel in ("torch-2.13.0-cp311-cp311-manylinux", "pin-4.1.0-0-cp311-cp311-manylinux", "ompl-2.0.1"):
        assert f"[aarch64] wheel   {wheel}" in out, wheel
    assert "[aarch64] sdist   ur_rtde-1.6.5.tar.gz" in out
    rclpy = "ros-jazzy-rclpy[fastrtps]==7.1.6 (ROS 2 Jazzy from source: rclpy rmw_fastrtps_cpp)"
    assert f"[aarch64] colcon  {rclpy}" in out


@pytest.mark.network
def test_a_pin_without_an_aarch64_wheel_or_route_fails(tmp_path):
    """PySide6-Essentials 6.11.3 (the ground station's) has x86_64 wheels only."""
    requirements = tmp_path / "gui.txt"
    requirements.write_text("pyyaml==6.0.3\nPySide6-Essentials==6.11.3\n")
    result = _check(str(requirements))
    assert result.returncode != 0
    assert (
        "[aarch64] FAILED: PySide6-Essentials==6.11.3 has no aarch64 wheel for CPython 3.11" in result.stderr
    ), result.stderr


def test_a_ros_wheel_without_a_colcon_route_fails_without_asking_the_registry(tmp_path):
    """The ros-jazzy-* wheels are pure Python over ros-* wheels that have no aarch64 builds: a pin
    of one alone would pass a dry run, so one without a route is refused by name."""
    requirements = tmp_path / "ros.txt"
    requirements.write_text("ros-jazzy-tf2-ros==0.36.0\n")
    result = _check(str(requirements))
    assert result.returncode != 0
    assert (
        "[aarch64] FAILED: ros-jazzy-tf2-ros==0.36.0: the ROS wheels have no aarch64 builds; give "
        "ros-jazzy-tf2-ros a colcon route in requirements/aarch64.txt" in result.stderr
    )


def test_every_route_belongs_to_a_pin_of_a_jetson_role():
    names = set()
    for role in ("robot", "vision"):
        files = subprocess.run(
            ["bash", str(ROOT / "scripts" / "setup.sh"), "--role", role, "--print-requirements"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split()
        for f in files:
            for raw in (ROOT / f).read_text().splitlines():
                line = raw.split("#", 1)[0].strip()
                if line:
                    names.add(re.split(r"[\[=<>!~;@ ]", line, maxsplit=1)[0].lower())
    routes = [line.split() for line in ROUTES.read_text().splitlines() if line.split("#", 1)[0].strip()]
    assert routes
    for name, kind, *what in routes:
        assert name in names, f"{name}: a route for no pin"
        assert kind in {"sdist", "colcon"} and what, name
