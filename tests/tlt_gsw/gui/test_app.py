"""``tlt gsw gui`` entry point: replay and live start-up, headless screenshots, bad input."""

from __future__ import annotations

import yaml
from PySide6 import QtGui

from tlt_gsw.gui import app


def test_replay_screenshot(qapp, demo, tmp_path, capsys):
    archive, definition = demo
    shot = tmp_path / "shots" / "tree.png"
    code = app.main([
        "--replay", str(archive.path), "--tree", f"crs={definition}", "--tab", "tree", "--size", "1200x800",
        "--screenshot", str(shot), "--screenshot-after", "2", "--refresh-hz", "50",
    ])  # fmt: skip
    assert code == app.EXIT_OK, capsys.readouterr().err
    image = QtGui.QImage(str(shot))
    assert (image.width(), image.height()) == (1200, 800)


def test_live_monitor_only_without_a_key(qapp, tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("TLT_GROUND_KEY_FILE", raising=False)
    config = tmp_path / "link.yaml"
    config.write_text(yaml.safe_dump({
        "key_file": "", "key_id": 1,
        "crs": {"bind_host": "127.0.0.1", "bind_port": 0, "replay_state": str(tmp_path / "r.json")},
        "gsw": {
            "crs_host": "127.0.0.1", "crs_port": 9, "bind_host": "127.0.0.1", "bind_port": 0,
            "archive": str(tmp_path / "live.sqlite"), "command_state": str(tmp_path / "seq.json"),
        },
    }))  # fmt: skip
    shot = tmp_path / "live.png"
    code = app.main([
        "--config", str(config), "--screenshot", str(shot), "--screenshot-after", "1", "--refresh-hz", "50",
    ])  # fmt: skip
    assert code == app.EXIT_OK, capsys.readouterr().err
    assert shot.stat().st_size > 0 and (tmp_path / "live.sqlite").exists()


def test_bad_input_is_a_clear_error(demo, tmp_path, capsys):
    archive, _ = demo
    assert app.main(["--replay", str(tmp_path / "none.sqlite")]) == app.EXIT_USAGE
    assert "does not exist" in capsys.readouterr().err
    assert app.main(["--replay", str(archive.path), "--tree", "crs"]) == app.EXIT_USAGE
    assert "AGENT=FILE" in capsys.readouterr().err
    assert app.main(["--replay", str(archive.path), "--plot", "hk_lifter.warp"]) == app.EXIT_USAGE
    assert "hk_lifter.warp" in capsys.readouterr().err
    assert app.main(["--replay", str(archive.path), "--tree", f"crs={tmp_path / 'x.json'}"]) == app.EXIT_USAGE
    assert "cannot read" in capsys.readouterr().err
