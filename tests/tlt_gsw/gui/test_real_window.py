"""The GUI in a real window on an X display (Xvfb), through Qt's xcb platform plugin, not only
offscreen: ``tlt gsw gui`` as an operator starts it, and the window tests drawn on the display."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent

pytestmark = pytest.mark.xdisplay


def test_tlt_gsw_gui_replays_an_archive_in_a_real_window(x_display, demo, tmp_path):
    """The reported failure: under X, Qt's xcb plugin aborted for want of libxcb-cursor0. The
    replay also names every node of the CRS tree with no definition file: the archive holds the
    definitions the CRS sent."""
    archive, _ = demo
    shot = tmp_path / "tree.png"
    script = (
        "import sys\n"
        "from PySide6 import QtGui, QtWidgets\n"
        "app = QtWidgets.QApplication(['tlt-gsw-gui'])\n"
        "from tlt_gsw.gui import app as gui\n"
        "code = gui.main(sys.argv[1:])\n"
        "print('platform', QtGui.QGuiApplication.platformName())\n"
        "sys.exit(code)\n"
    )
    args = ["--replay", str(archive.path), "--tab", "tree", "--size", "1200x800", "--screenshot", str(shot)]
    run = subprocess.run(
        [sys.executable, "-c", script, *args], env=x_display, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "platform xcb" in run.stdout and "qt.qpa" not in run.stderr, run.stdout + run.stderr
    from PySide6 import QtGui

    image = QtGui.QImage(str(shot))
    assert (image.width(), image.height()) == (1200, 800)


def test_the_window_tests_pass_drawn_on_the_display(x_display):
    """The main window's and the entry point's tests, in a process whose Qt draws real windows."""
    env = x_display | {"QT_QPA_PLATFORM": "xcb"}
    files = [str(HERE / name) for name in ("test_main_window.py", "test_app.py")]
    run = subprocess.run(
        [sys.executable, "-m", "pytest", *files, "-q", "-x", "-p", "no:cacheprovider"],
        env=env,
        capture_output=True,
        text=True,
        timeout=400,
        cwd=HERE.parents[2],
    )
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    assert " passed" in run.stdout and "skipped" not in run.stdout
