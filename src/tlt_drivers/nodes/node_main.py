"""Shared ``main`` of the driver nodes: parse ``--config``/``--port``, spin until shutdown, exit cleanly.

``--config`` defaults to the node's file under the repository's ``config/hardware/``; ``--port``
replaces the YAML's serial port (e.g. the pty symlink of an emulated chain in a launch set).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from tlt_common.config_schema import ConfigError
from tlt_common.interpreter_lock import share_the_interpreter_quickly

HARDWARE_CONFIG_DIR = Path(__file__).resolve().parents[3] / "config" / "hardware"


def run_node(
    name: str,
    default_config: str,
    load: Callable[[Path], dict[str, Any]],
    build: Callable[[dict[str, Any]], Node],
    argv: list[str] | None = None,
) -> int:
    """Load ``--config`` (default ``config/hardware/<default_config>``), build the node, spin it.

    Returns 0 after a clean shutdown, 2 when the configuration is unreadable or invalid.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    user_args = rclpy.utilities.remove_ros_args(["prog", *argv])[1:]
    parser = argparse.ArgumentParser(prog=name, description=f"TLT {name} driver node")
    parser.add_argument(
        "--config", type=Path, default=HARDWARE_CONFIG_DIR / default_config, help="hardware YAML"
    )
    parser.add_argument("--port", help="serial port to use instead of the YAML's")
    parser.add_argument(
        "--latency-timer-ms", type=float,
        help="Dynamixel chains: the latency the packet timeout allows for, instead of the YAML's (comm."
        "latency_timer_ms); on the twin the far end is a process sharing the CPU, not a USB adapter",
    )
    args = parser.parse_args(user_args)
    try:
        config = load(args.config)
    except ConfigError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return 2
    if args.port:
        config["port"] = args.port
    if args.latency_timer_ms is not None:
        if "latency_timer_ms" not in config.get("comm", {}):
            print(f"{name}: --latency-timer-ms applies to Dynamixel chains only", file=sys.stderr)
            return 2
        config["comm"]["latency_timer_ms"] = args.latency_timer_ms
    share_the_interpreter_quickly()  # the serial reader and the executor share it
    rclpy.init(args=["prog", *argv])
    node = None
    try:
        node = build(config)
        rclpy.spin(node)
    except ConfigError as exc:  # a file the node opens while building (e.g. the EE's GPIO map)
        print(f"{name}: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM shut the context down while a callback was publishing: a normal stop.
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
