"""The optional viewer: refused with a one-line reason where no window can open (this machine is
headless), and the sync that feeds a window, checked against a stand-in handle (the window itself
is MuJoCo's and not under test here)."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import pytest
import yaml
from tlt_sim.twin.main import main
from tlt_sim.twin.settings import DEFAULT_SETTINGS, load_settings
from tlt_sim.twin.viewer import ViewerSync, ViewerUnavailable, display_problem, open_viewer, probe

from tlt_common.config_schema import ConfigError


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class FakeCamera:
    def __init__(self) -> None:
        self.lookat = [0.0, 0.0, 0.0]
        self.distance = self.azimuth = self.elevation = 0.0


class FakeHandle:
    """Records what the sync does with the viewer's handle."""

    def __init__(self) -> None:
        self.running = True
        self.syncs = 0
        self.closes = 0
        self.cam = FakeCamera()
        self.locked = 0

    @contextlib.contextmanager
    def lock(self):
        self.locked += 1
        yield

    def is_running(self) -> bool:
        return self.running

    def sync(self) -> None:
        self.syncs += 1

    def close(self) -> None:
        self.closes += 1
        self.running = False


def _free_display() -> str:
    """An X display number with no server behind it."""
    n = 90
    while Path(f"/tmp/.X11-unix/X{n}").exists():
        n += 1
    return f":{n}"


def test_no_display_named_is_a_reason():
    assert "DISPLAY" in display_problem({})
    assert display_problem({"DISPLAY": ":0"}) is None
    assert display_problem({"WAYLAND_DISPLAY": "wayland-0"}) is None


def test_probe_refuses_without_a_display():
    with pytest.raises(ViewerUnavailable, match="no display"):
        probe({})


def test_probe_refuses_a_display_nobody_serves(monkeypatch):
    display = _free_display()
    monkeypatch.setenv("DISPLAY", display)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(ViewerUnavailable) as err:
        probe()
    assert "GLFW" in str(err.value) and "\n" not in str(err.value)


def test_twin_with_viewer_refuses_to_start_headless(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    run = tmp_path / "run"
    assert main(["--viewer", "--run-dir", str(run)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tlt twin run: no viewer:") and "DISPLAY" in err
    assert len(err.splitlines()) == 1
    assert not run.exists(), "nothing was started"


def test_viewer_enabled_in_run_yaml_is_refused_the_same(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    doc = yaml.safe_load(DEFAULT_SETTINGS.read_text())
    doc["viewer"] = {"enabled": True}
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert load_settings(path).viewer and load_settings(path).viewer_rate_hz == 30.0
    assert main(["--settings", str(path), "--run-dir", str(tmp_path / "run")]) == 2
    assert "no viewer" in capsys.readouterr().err


@pytest.mark.parametrize("viewer_doc", [{"enabled": "yes"}, {"rate_hz": 0.0}, {"fps": 30}])
def test_bad_viewer_settings_are_refused(tmp_path, viewer_doc):
    doc = yaml.safe_load(DEFAULT_SETTINGS.read_text())
    doc["viewer"] = viewer_doc
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as err:
        load_settings(path)
    assert str(path) in str(err.value) and "viewer." in str(err.value)


def test_shipped_settings_leave_the_viewer_off():
    assert load_settings().viewer is False


def test_sync_is_rate_limited_by_wall_clock():
    clock, handle = FakeClock(), FakeHandle()
    sync = ViewerSync(handle, rate_hz=30.0, clock=clock)
    synced = 0
    for _ in range(1000):  # one second of wall time in 1 ms periods
        synced += sync.maybe_sync()
        clock.t += 0.001
    assert handle.syncs == synced == sync.syncs
    assert 29 <= synced <= 31


def test_sync_does_not_catch_up_after_a_stall():
    clock, handle = FakeClock(), FakeHandle()
    sync = ViewerSync(handle, rate_hz=10.0, clock=clock)
    assert sync.maybe_sync()
    clock.t += 5.0  # the loop stalled for 5 s
    assert sync.maybe_sync()
    assert not sync.maybe_sync(), "one frame after a stall, not fifty"
    clock.t += 0.1
    assert sync.maybe_sync()


def test_closed_window_stops_syncing_and_close_is_idempotent():
    clock, handle = FakeClock(), FakeHandle()
    sync = ViewerSync(handle, rate_hz=30.0, clock=clock)
    assert sync.maybe_sync()
    handle.running = False  # the person closed the window
    clock.t += 1.0
    assert not sync.maybe_sync() and not sync.open
    assert handle.syncs == 1
    sync.close()
    assert handle.closes == 0, "a window the person closed is not closed again"

    other = ViewerSync(FakeHandle(), clock=clock)
    other.close()
    other.close()
    assert other.handle.closes == 1 and not other.maybe_sync()


def test_bad_rate_is_refused():
    with pytest.raises(ValueError):
        ViewerSync(FakeHandle(), rate_hz=0.0)


def test_open_viewer_passes_model_and_data_and_reports_a_failed_launch():
    seen = {}

    def launch(model, data, **kw):
        seen.update(model=model, data=data, **kw)
        return FakeHandle()

    view = {"lookat": [0.4, 0.4, 1.0], "distance": 5.0, "azimuth": 135.0, "elevation": -25.0}
    sync = open_viewer("model", "data", rate_hz=20.0, view=view, launch=launch)
    assert seen["model"] == "model" and seen["data"] == "data"
    assert sync.period == pytest.approx(0.05)
    cam = sync.handle.cam
    assert cam.lookat[:] == [0.4, 0.4, 1.0]
    assert (cam.distance, cam.azimuth, cam.elevation) == (5.0, 135.0, -25.0)
    assert sync.handle.locked == 1, "the camera is set under the viewer's lock"

    def refuse(model, data, **kw):
        raise RuntimeError("could not initialize GLFW")

    with pytest.raises(ViewerUnavailable, match="could not initialize GLFW"):
        open_viewer("model", "data", launch=refuse)


def test_open_viewer_never_waits_for_ever():
    import threading

    release = threading.Event()

    def hang(model, data, **kw):  # a window thread that never hands back its handle
        release.wait(5.0)
        return FakeHandle()

    try:
        with pytest.raises(ViewerUnavailable, match="did not open within"):
            open_viewer("model", "data", timeout_s=0.2, launch=hang)
    finally:
        release.set()


_WINDOW_SCRIPT = """
import time, mujoco
from tlt_sim.twin.viewer import open_viewer, probe
probe()
model = mujoco.MjModel.from_xml_string(
    '<mujoco><worldbody><body><freejoint/><geom size="0.1"/></body></worldbody></mujoco>')
data = mujoco.MjData(model)
view = open_viewer(model, data, rate_hz=50.0,
                   view={"lookat": [0, 0, 0], "distance": 2.0, "azimuth": 90.0, "elevation": -20.0})
end = time.monotonic() + 1.0
while time.monotonic() < end:
    mujoco.mj_step(model, data)
    view.maybe_sync()
    time.sleep(0.002)
assert view.handle.is_running(), "window still open"
assert 10 <= view.syncs <= 60, view.syncs
view.close()
time.sleep(0.5)
assert not view.handle.is_running()
print("window ok", view.syncs)
"""


def test_a_real_window_opens_syncs_and_closes_under_xvfb(tmp_path):
    """Under Xvfb (scripts/setup.sh installs it; skipped where it is missing), MuJoCo's own viewer
    window opens on a display, takes synced frames and closes."""
    import shutil
    import subprocess
    import sys
    import time

    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed")
    display = _free_display()
    server = subprocess.Popen(
        ["Xvfb", display, "-screen", "0", "640x480x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 10.0
        while not Path(f"/tmp/.X11-unix/X{display[1:]}").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        env = {k: v for k, v in os.environ.items() if k != "WAYLAND_DISPLAY"}
        env["DISPLAY"] = display
        run = subprocess.run(
            [sys.executable, "-c", _WINDOW_SCRIPT], env=env, capture_output=True, text=True, timeout=60
        )
        assert run.returncode == 0, run.stdout + run.stderr
        assert "window ok" in run.stdout
    finally:
        server.terminate()
        server.wait(timeout=10)
