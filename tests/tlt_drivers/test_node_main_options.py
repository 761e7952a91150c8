"""Driver node command line: the overrides a launch set passes (port, Dynamixel latency, MightyZAP
response timeout)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tlt_drivers import node_main


def test_latency_override_applies_to_dynamixel_chains_only():
    def load(path):
        return {"component": "camera_mounts", "port": "/dev/x", "comm": {"latency_timer_ms": 16.0}}

    driver = node_main.chain_driver(
        "cams",
        "camera_mounts.yaml",
        load,
        lambda config: config,
        ["--port", "/tmp/p", "--latency-timer-ms", "60"],
    )
    config = driver.build()  # this build hands back the configuration it was given
    assert driver.name == "camera_mounts"
    assert config["port"] == "/tmp/p" and config["comm"]["latency_timer_ms"] == 60.0
    with pytest.raises(node_main.DriverStartError, match="applies to Dynamixel chains only"):
        node_main.chain_driver(
            "zap",
            "top_grippers.yaml",
            lambda path: {"component": "top_grippers", "port": "/dev/x"},
            lambda config: config,
            ["--latency-timer-ms", "60"],
        )
    assert Path(node_main.HARDWARE_CONFIG_DIR / "camera_mounts.yaml").is_file()


def test_response_timeout_override_applies_to_mightyzap_chains_only():
    def load(path):
        return {"component": "top_grippers", "port": "/dev/x", "comm": {"response_timeout_s": 0.05}}

    driver = node_main.chain_driver(
        "zap", "top_grippers.yaml", load, lambda config: config, ["--response-timeout-s", "0.2"]
    )
    assert driver.build()["comm"]["response_timeout_s"] == 0.2
    with pytest.raises(node_main.DriverStartError, match=r"0\.001 to 1 s, not 0\.0"):
        node_main.chain_driver("zap", "top_grippers.yaml", load, lambda c: c, ["--response-timeout-s", "0"])
    with pytest.raises(node_main.DriverStartError, match="applies to MightyZAP chains only"):
        node_main.chain_driver(
            "cams",
            "camera_mounts.yaml",
            lambda path: {"component": "camera_mounts", "port": "/dev/x", "comm": {"latency_timer_ms": 16.0}},
            lambda config: config,
            ["--response-timeout-s", "0.2"],
        )
