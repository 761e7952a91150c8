"""Shared fixtures of the GUI tests: Qt offscreen, one QApplication, a demo archive."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")  # before anything imports Qt

import pytest

from tlt_common.ccsds.definitions import load_definitions
from tlt_gsw.gui.demo_archive import write_demo_archive

DEFS = load_definitions()


@pytest.fixture(scope="session")
def qapp():
    from PySide6 import QtWidgets

    from tlt_gsw.gui.qt_check import binding_problem

    problem = binding_problem()
    if problem is not None:
        pytest.fail(problem)
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(["tlt-gsw-gui-tests"])
    yield app


@pytest.fixture(scope="module")
def x_display():
    """An X display for real windows: ``$DISPLAY`` when one is set, else an Xvfb server started
    here (scripts/setup.sh installs it, with the libraries Qt's xcb platform plugin loads).
    Yields the environment a child process needs to draw on it with Qt's xcb plugin."""
    import shutil
    import subprocess
    import time
    from pathlib import Path

    env = {k: v for k, v in os.environ.items() if k not in ("QT_QPA_PLATFORM", "WAYLAND_DISPLAY")}
    if os.environ.get("DISPLAY"):
        yield env
        return
    if shutil.which("Xvfb") is None:
        pytest.fail("no X display and no Xvfb to start one: run scripts/setup.sh (it installs xvfb)")
    number = 90
    while Path(f"/tmp/.X11-unix/X{number}").exists() or Path(f"/tmp/.X{number}-lock").exists():
        number += 1
    server = subprocess.Popen(
        ["Xvfb", f":{number}", "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 15.0
        while not Path(f"/tmp/.X11-unix/X{number}").exists():
            if server.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"Xvfb :{number} did not start: {server.stderr.read().decode(errors='replace')}")
            time.sleep(0.05)
        yield env | {"DISPLAY": f":{number}"}
    finally:
        server.terminate()
        server.wait(timeout=10)


@pytest.fixture(scope="session")
def demo(tmp_path_factory):
    """A 40 s demo archive (real packets) and its CRS tree definition file."""
    folder = tmp_path_factory.mktemp("demo")
    archive = write_demo_archive(
        folder / "demo.sqlite", seconds=40.0, start=1_800_000_000.0, tree_definition=folder / "crs.json"
    )
    return archive, folder / "crs.json"


class CrsEnd:
    """A real CRS ground link on loopback UDP that acknowledges commands as a CRS would.

    start/pause/resume/stop complete; set_blackboard_value is refused by the validator unless the
    key is ``lifter_speed``; set_actuator_state fails for the lifter (it is in Safe) and completes
    otherwise. ``handled`` lists the commands that reached the "tree".
    """

    def __init__(self, tmp_path, key_file) -> None:
        from tlt_common.ccsds.auth import KeyRing
        from tlt_common.ccsds.reasons import Reason
        from tlt_crs.ground_link import GroundLink

        self.handled = []

        def validator(command):
            if command.name == "set_blackboard_value" and command.params["key"] != "lifter_speed":
                return Reason.REFUSED, f"{command.params['key']} is not ground-writable"
            return None

        def handler(command):
            self.handled.append(command)
            if command.name == "set_actuator_state" and command.params["actuator"] == "lifter":
                self.link.complete(command, False, Reason.EXECUTION_FAILED, "lifter is in Safe")
            else:
                self.link.complete(command, detail="done")

        self.link = GroundLink(
            DEFS, KeyRing.load(key_file), tmp_path / "replay.json", on_command=handler, validator=validator,
            stats_period_s=0,
        )  # fmt: skip
        self.link.start()

    def close(self) -> None:
        self.link.close()


@pytest.fixture
def link_pair(tmp_path):
    """(CrsEnd, LinkWorker, archive path): both ends of the link on 127.0.0.1, the GSW recording."""
    from tlt_common.ccsds.auth import CommandSequencer, KeyRing, write_key_file
    from tlt_gsw.archive.recorder import Recorder
    from tlt_gsw.gui.link_worker import LinkWorker
    from tlt_gsw.link import GswLink

    key_file = write_key_file(tmp_path / "keys" / "ground.key", {1: os.urandom(32)}, {1: os.urandom(32)})
    crs = CrsEnd(tmp_path, key_file)
    archive = tmp_path / "archive.sqlite"
    link = GswLink(
        DEFS, KeyRing.load(key_file), 1, crs.link.address, recorder=Recorder(archive, flush_interval_s=0.05),
        close_recorder=True, sequencer=CommandSequencer(tmp_path / "seq.json"),
    )  # fmt: skip
    crs.link.gsw_address = link.address
    worker = LinkWorker(link).start()
    yield crs, worker, archive
    worker.close()
    crs.close()


def _wait_for(predicate, timeout: float = 10.0, step: float = 0.02, pump=None):
    """Poll ``predicate`` (calling ``pump`` between polls) until it is truthy; fail after ``timeout``."""
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pump is not None:
            pump()
        value = predicate()
        if value:
            return value
        time.sleep(step)
    raise AssertionError(f"condition not met within {timeout} s")


@pytest.fixture
def wait_for():
    return _wait_for


@pytest.fixture
def make_crs(tmp_path):
    """Factory of :class:`CrsEnd` for a given key file; closed after the test."""
    made = []

    def make(key_file):
        crs = CrsEnd(tmp_path, key_file)
        made.append(crs)
        return crs

    yield make
    for crs in made:
        crs.close()
