"""The emulated UR controller's dashboard server protocol (port 29999): the answer to each
request line, as a UR e-Series controller gives it."""

from __future__ import annotations

from typing import Protocol

from tlt_sim.emulators.ur_controller_config import URControllerConfig


class DashboardController(Protocol):
    """What the dashboard reads and drives on the controller."""

    config: URControllerConfig
    protective_stopped: bool
    program_text: str

    @property
    def program_running(self) -> bool: ...

    def stop_program(self, reason: str = ...) -> None: ...

    def play(self) -> bool: ...

    def unlock_protective_stop(self) -> str: ...


def dashboard_answer(ur: DashboardController, request: str) -> str:
    """The dashboard server's answer to one request line."""
    """The dashboard server's answer to one request line."""
    major, minor, bugfix, build = ur.config.version
    req = request.strip()
    low = req.lower()
    running = ur.program_running
    if req == "PolyscopeVersion":
        return f"URSoftware {major}.{minor}.{bugfix}.{build} (Jan 01 2023)"
    if low == "get serial number":
        return ur.config.serial_number
    if low == "is in remote control":
        return "true" if ur.config.remote_control else "false"
    if low == "get robot model":
        return "UR10"
    if low == "robotmode":
        return "Robotmode: RUNNING"
    if low == "safetymode":
        return "Safetymode: PROTECTIVE_STOP" if ur.protective_stopped else "Safetymode: NORMAL"
    if low == "safetystatus":
        return "Safetystatus: PROTECTIVE_STOP" if ur.protective_stopped else "Safetystatus: NORMAL"
    if low == "programstate":
        return "PLAYING rtde_control" if running else "STOPPED rtde_control"
    if low == "running":
        return f"Program running: {'true' if running else 'false'}"
    if low == "stop":
        ur.stop_program("stopped from the dashboard")
        return "Stopped"
    if low == "pause":
        return "Failed to execute: pause"
    if low == "play":
        return "Starting program" if ur.play() else "Failed to execute: play"
    if low == "unlock protective stop":
        return ur.unlock_protective_stop()
    if low == "close safety popup":
        return "closing safety popup"
    if low == "close popup":
        return "closing popup"
    if low.startswith("popup "):
        return "showing popup"
    if low == "power on":
        return "Powering on"
    if low == "power off":
        return "Powering off"
    if low == "brake release":
        return "Brake releasing"
    if low == "restart safety":
        return "Restarting safety"
    if low == "get loaded program":
        return "Loaded program: rtde_control" if ur.program_text else "No program loaded"
    if low == "isprogramsaved":
        return "true rtde_control"
    if low.startswith("addtolog "):
        return "Added log message"
    if low.startswith("setuserrole "):
        return f"Setting user role: {req.split(' ', 1)[1]}"
    if low == "quit":
        return "Disconnected"
    return f"could not understand: '{req}'"


__all__ = ["DashboardController", "dashboard_answer"]
