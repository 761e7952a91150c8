"""The live view in a browser (docs/live-view.md, issue 69's goal): a twin process, tlt-live-bridge
and tlt-live-viewer running, headless Chromium opens the viewer's page, which talks Foxglove's
WebSocket protocol to the bridge; its screenshot shows the EDU and the parts where a page with no
bridge shows only the floor grid, and an arm moved through its controller (the real ur-rtde
library against the twin) moves in the page to where the twin has it."""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from contextlib import ExitStack, suppress
from pathlib import Path

import cv2
import numpy as np
import rtde_control
import rtde_receive
from tlt_sim.model.scene import Scene
from websockets.sync.client import connect

from tlt_common.live_viewer.server import LiveViewerServer

BROWSERS = ("chromium-headless-shell", "chromium")
WINDOW = (1024, 640)
BACKGROUND = np.array([0x27, 0x21, 0x1D])  # the page's background, BGR
STATUS_ROWS = 28  # the page's status line, at the top
ARM_X_HOST = "127.0.76.4"  # loopback addresses no other test file's emulated arms use
TWIN_ARGS = ["--rtf", "1", "--duration", "300", "--ur-x-host", ARM_X_HOST, "--ur-y-host", "127.0.76.5"]
BRIDGE_ARGS = ["--port", "0", "--topics", "/tf", "/tf_static", "/robot_description", "/twin/markers"]
BRIDGE_ARGS += ["--ros-args", "-p", "use_sim_time:=true"]
# Frames at the end of chains of moving joints, whose drawn positions are checked.
FRAMES = ["ars_x/link_6", "ars_y/jaw_a", "lifter_carriage_0", "top_gripper_1", "payload"]
# Where a screenshot is kept for docs/images when TLT_LIVE_VIEWER_SCREENSHOT names a file.
SCREENSHOT_ENV = "TLT_LIVE_VIEWER_SCREENSHOT"


def _browser() -> str:
    found = [shutil.which(b) for b in BROWSERS]
    path = next((p for p in found if p), None)
    assert path, f"none of {BROWSERS} is installed: scripts/setup.sh installs requirements/apt.txt"
    return path


class _DevTools:
    """One page of a headless Chromium, driven over the DevTools protocol."""

    def __init__(self, user_dir: Path) -> None:
        self._stack = ExitStack()
        self.proc = subprocess.Popen(
            [
                _browser(),
                "--headless",
                "--no-sandbox",  # tests run as root in containers, where Chromium's sandbox cannot
                "--remote-debugging-port=0",
                f"--user-data-dir={user_dir}",
                f"--window-size={WINDOW[0]},{WINDOW[1]}",
                "--use-angle=swiftshader",  # WebGL on the CPU: no GPU needed
                "--enable-unsafe-swiftshader",
                "about:blank",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # its own process group: its GPU and renderer processes end with it
        )
        self._stack.callback(self._end_browser)
        try:
            self._attach()
        except BaseException:
            self._stack.close()
            raise

    def _attach(self) -> None:
        deadline = time.monotonic() + 30.0
        browser_ws = ""
        while not browser_ws:
            line = self.proc.stderr.readline()
            assert line or self.proc.poll() is None, "Chromium ended before it listened"
            found = re.search(r"DevTools listening on (ws://\S+)", line)
            browser_ws = found.group(1) if found else ""
            assert time.monotonic() < deadline, "Chromium never listened for DevTools"
        threading.Thread(target=self.proc.stderr.read, daemon=True).start()  # keep its pipe drained
        self.browser = self._stack.enter_context(connect(browser_ws, max_size=None, open_timeout=10))
        self._id = 0
        target = self.call("Target.createTarget", url="about:blank", session=None)["targetId"]
        attached = self.call("Target.attachToTarget", targetId=target, flatten=True, session=None)
        self.session = attached["sessionId"]

    def call(self, method: str, session: str | None = "", **params) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params}
        if session is not None:
            msg["sessionId"] = session or self.session
        self.browser.send(json.dumps(msg))
        while True:
            reply = json.loads(self.browser.recv(timeout=30))
            if reply.get("id") == self._id:
                assert "error" not in reply, (method, reply["error"])
                return reply["result"]

    def evaluate(self, expression: str):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        return result["result"].get("value")

    def screenshot(self) -> np.ndarray:
        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)

    def open(self, url: str) -> None:
        self.call("Page.navigate", url=url)

    def _end_browser(self) -> None:
        os.killpg(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout=10)
        finally:
            with suppress(ProcessLookupError):  # a child that stayed behind
                os.killpg(self.proc.pid, signal.SIGKILL)

    def __enter__(self) -> _DevTools:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()


def _stats_until(page: _DevTools, condition, timeout_s: float, what: str, offset: str = "") -> dict:
    """The page's counts once ``condition`` holds of them; with ``offset`` (a JavaScript expression
    of a vector) its length too, as ``moved``."""
    deadline = time.monotonic() + timeout_s
    stats: dict = {}
    while time.monotonic() < deadline:
        stats = page.evaluate("window.tltViewer ? window.tltViewer.stats() : null") or {}
        if stats and offset:
            stats["moved"] = float(np.linalg.norm(page.evaluate(offset)))
        if stats and condition(stats):
            return stats
        time.sleep(0.2)
    raise AssertionError(f"{what}; the page says {stats}")


def _scene_pixels(image: np.ndarray) -> tuple[float, float]:
    """The fractions of the picture below the status line that show something brighter than the
    floor grid (whose lines are at most 63 levels from the background), and that show a colour
    (the parts' ends, rivets, the payload's fittings: not the grey of the arms and the grid)."""
    below = image[STATUS_ROWS:]
    far = np.abs(below.astype(int) - BACKGROUND).max(axis=2) > 70
    saturated = cv2.cvtColor(below, cv2.COLOR_BGR2HSV)[..., 1] > 100
    return float(far.mean()), float((far & saturated).mean())


def _start(cmd: list[str]) -> subprocess.Popen:
    return subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ)
    )


def _line(proc: subprocess.Popen, pattern: str, timeout_s: float) -> re.Match:
    """The first line of ``proc``'s output that matches ``pattern``; what it printed before is
    kept for the failure message."""
    seen: list[str] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        seen.append(line)
        found = re.search(pattern, line)
        if found:
            threading.Thread(target=proc.stdout.read, daemon=True).start()
            return found
    raise AssertionError(f"no line matching {pattern!r}:\n{''.join(seen[-30:])}")


def _stop(proc: subprocess.Popen) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


def test_headless_chromium_sees_the_edu_the_tower_and_the_arms_through_the_bridge(tmp_path):
    statuses: dict[str, int] = {}
    with ExitStack() as stack:
        twin = _start(
            [sys.executable, "-m", "tlt_sim.twin.main", "--run-dir", str(tmp_path / "run"), *TWIN_ARGS]
        )
        stack.callback(lambda: statuses.update(twin=_stop(twin)))
        bridge = _start([sys.executable, "-m", "tlt_common.foxglove_bridge", *BRIDGE_ARGS])
        stack.callback(lambda: statuses.update(bridge=_stop(bridge)))
        _line(twin, r"links up", 60.0)
        bridge_port = int(_line(bridge, r"open ws://127\.0\.0\.1:(\d+)", 30.0).group(1))
        viewer = LiveViewerServer(port=0, bridge_port=bridge_port)
        stack.callback(viewer.server_close)
        threading.Thread(target=viewer.serve_forever, daemon=True).start()
        stack.callback(viewer.shutdown)
        page = stack.enter_context(_DevTools(tmp_path / "chromium"))

        # With no bridge to talk to, the page shows the floor grid and its status line only.
        page.open(f"{viewer.address}?ws=ws://127.0.0.1:9")
        _stats_until(page, lambda s: "no bridge" in s["connection"], 20.0, "the page never gave up on port 9")
        assert _scene_pixels(page.screenshot()) == (0.0, 0.0)

        page.open(viewer.address)
        first = _stats_until(
            page,
            lambda s: s["robotVisuals"] > 50 and s["markers"] > 20 and s["tfMessages"] >= 3,
            60.0,
            "the page never showed the EDU and the parts",
        )
        assert first["connection"] == f"connected to ws://127.0.0.1:{bridge_port}"
        assert not first["errors"]
        # Every shape hangs from a frame joined to world: meshesInWorld counts only those.
        assert first["meshesInWorld"] >= first["robotVisuals"] + first["markers"]
        # ARS X's arm turns (moveJ through its UR controller): the page follows /tf.
        before = np.array(page.evaluate('window.tltViewer.worldPosition("ars_x/link_6")'))
        receive = rtde_receive.RTDEReceiveInterface(ARM_X_HOST)
        stack.callback(receive.disconnect)
        control = rtde_control.RTDEControlInterface(ARM_X_HOST)
        stack.callback(control.disconnect)
        target = np.array(receive.getActualQ()) + np.array([0.8, 0.0, -0.5, 0.0, 0.0, 0.0])
        assert control.moveJ(target.tolist(), 1.0, 2.0)  # returns once the arm stands there
        arm_q = np.array(receive.getActualQ())
        stopped = page.evaluate("window.tltViewer.stats().simTime")
        moved = _stats_until(
            page,
            lambda s: s["simTime"] >= stopped + 0.5 and s["moved"] > 0.3,
            20.0,
            "the arm did not move in the page",
            f"window.tltViewer.worldPosition('ars_x/link_6').map((v, i) => v - {before.tolist()}[i])",
        )
        assert moved["tfMessages"] > first["tfMessages"]
        drawn = page.evaluate(f"{json.dumps(FRAMES)}.map((f) => window.tltViewer.worldPosition(f))")
        _stats_until(page, lambda s: s["viewFitted"], 10.0, "the view never fitted itself to the scene")
        shot = page.screenshot()
        keep = os.environ.get(SCREENSHOT_ENV)
        if keep:
            cv2.imwrite(keep, shot)
        assert shot.shape[:2] == (WINDOW[1], WINDOW[0])
        shown, coloured = _scene_pixels(shot)
        assert shown > 0.04, f"only {shown:.1%} of the screenshot shows the scene"
        assert coloured > 0.002, f"only {coloured:.2%} of the screenshot shows the parts' colours"
    assert statuses == {"bridge": 0, "twin": 0}
    # The page puts the arms' links, the lifter's carriages and the payload where the twin has them
    # (its first pose, ARS X's arm where the controller says it stopped): /tf_static and /tf
    # composed through every joint from world.
    with Scene(out_dir=tmp_path / "model") as scene:
        scene.pose_arm("ars_x", arm_q)
        for frame, position in zip(FRAMES, drawn, strict=True):
            assert position is not None, f"{frame} is not joined to world in the page"
            assert np.allclose(position, scene.body_pose(frame)[0], atol=0.002), frame
