"""Driver node command line: the overrides a launch set passes (port, Dynamixel latency)."""

from __future__ import annotations

from pathlib import Path

from tlt_drivers.nodes import node_main


def test_latency_override_applies_to_dynamixel_chains_only(capsys, monkeypatch):
    seen = {}

    def build(config):
        seen.update(config)
        raise KeyboardInterrupt  # stop before spinning: the options are what is tested

    monkeypatch.setattr(node_main.rclpy, "spin", lambda node: None)
    status = node_main.run_node(
        "cams", "camera_mounts.yaml",
        lambda path: {"port": "/dev/x", "comm": {"latency_timer_ms": 16.0}},
        build, ["--port", "/tmp/p", "--latency-timer-ms", "60"],
    )
    assert status == 0 and seen["port"] == "/tmp/p" and seen["comm"]["latency_timer_ms"] == 60.0
    status = node_main.run_node(
        "zap", "top_grippers.yaml", lambda path: {"port": "/dev/x"}, build, ["--latency-timer-ms", "60"]
    )
    assert status == 2
    assert "applies to Dynamixel chains only" in capsys.readouterr().err
    assert Path(node_main.HARDWARE_CONFIG_DIR / "camera_mounts.yaml").is_file()
