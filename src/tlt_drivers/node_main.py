"""How a driver process starts, spins and stops, with one driver node (``tlt-lifter``) or several.

A driver is parsed from its own arguments into a :class:`Driver` (its configuration loaded and
checked, nothing opened yet); :func:`spin_drivers` then builds each node and spins it on an
executor and thread of its own, as rclcpp's isolated component container does. One thread per
node because a driver blocks in its control loop on a serial exchange (a MightyZAP board that
stops answering holds its loop for the 50 ms response timeout): on one executor that would hold
the lifter's 50 Hz command stream past the firmware's 40 ms watchdog. One process for several
(``tlt-drivers``) because every process is a DDS participant of its own, woken for every
``/clock`` step and discovery change, so fewer processes for the eight drivers take less of the
idle system's CPU than eight (docs/system.md says why the launch sets keep eight).

A bad argument or configuration is a message and exit code 2, never a traceback; a node whose
callback raises takes the process down with exit code 1 (the launcher restarts it) after every
node has been shut down.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from tlt_common.config_schema import ConfigError
from tlt_common.ros.direct_executor import DirectExecutor
from tlt_common.ros.interpreter_lock import share_the_interpreter_quickly
from tlt_common.ros.rosout_logging import RosoutHandler, forward_logging_to_rosout, init_rclpy

HARDWARE_CONFIG_DIR = Path(__file__).resolve().parents[2] / "config" / "hardware"

#: How long the nodes' shutdowns may take together. ur-rtde's disconnect from a controller that has
#: gone waits on its own reconnect attempts; the controller stops the arm by itself when the
#: script's connection drops, so a process never hangs on it.
SHUTDOWN_TIMEOUT_S = 3.0


class DriverStartError(Exception):
    """A driver that cannot start: bad arguments, an invalid configuration, a device it cannot open."""


@dataclass(frozen=True)
class Driver:
    """One driver, parsed and configured: ``build`` makes its node once rclpy is initialised."""

    name: str
    build: Callable[[], Node]


def _own_arguments(prog: str, argv: Sequence[str]) -> list[str]:
    """``argv`` without its ROS arguments (``--ros-args ...``), which rclpy takes."""
    return rclpy.utilities.remove_ros_args([prog, *argv])[1:]


def chain_driver(
    name: str,
    default_config: str,
    load: Callable[[Path], dict[str, Any]],
    build: Callable[[dict[str, Any]], Node],
    args: Sequence[str],
) -> Driver:
    """A Dynamixel or MightyZAP chain driver from its arguments: ``--config`` (default
    ``config/hardware/<default_config>``), ``--port`` (the YAML's port replaced, e.g. by an
    emulated chain's pty), ``--latency-timer-ms`` (Dynamixel), ``--response-timeout-s`` (MightyZAP).
    Raises :class:`DriverStartError`."""
    parser = argparse.ArgumentParser(prog=name, description=f"TLT {name} driver node")
    parser.add_argument(
        "--config", type=Path, default=HARDWARE_CONFIG_DIR / default_config, help="hardware YAML"
    )
    parser.add_argument("--port", help="serial port to use instead of the YAML's")
    parser.add_argument(
        "--latency-timer-ms",
        type=float,
        help="Dynamixel chains: the latency the packet timeout allows for, instead of the YAML's (comm."
        "latency_timer_ms); on the twin the far end is a process sharing the CPU, not a USB adapter",
    )
    parser.add_argument(
        "--response-timeout-s",
        type=float,
        help="MightyZAP chains: how long a request waits for feedback, instead of the YAML's (comm."
        "response_timeout_s); on the twin the far end is a process sharing the CPU, not an actuator",
    )
    parsed = parser.parse_args(list(args))
    try:
        config = load(parsed.config)
    except ConfigError as exc:
        raise DriverStartError(str(exc)) from exc
    if parsed.port:
        config["port"] = parsed.port
    if parsed.latency_timer_ms is not None:
        if "latency_timer_ms" not in config.get("comm", {}):
            raise DriverStartError("--latency-timer-ms applies to Dynamixel chains only")
        config["comm"]["latency_timer_ms"] = parsed.latency_timer_ms
    if parsed.response_timeout_s is not None:
        if "response_timeout_s" not in config.get("comm", {}):
            raise DriverStartError("--response-timeout-s applies to MightyZAP chains only")
        if not 0.001 <= parsed.response_timeout_s <= 1.0:  # the YAML's bounds
            raise DriverStartError(
                f"--response-timeout-s must be 0.001 to 1 s, not {parsed.response_timeout_s}"
            )
        config["comm"]["response_timeout_s"] = parsed.response_timeout_s
    return Driver(config["component"], lambda: build(config))


def run_drivers(
    prog: str, parse: Callable[[list[str]], Sequence[Driver]], argv: Sequence[str] | None = None
) -> int:
    """The ``main`` of a driver executable: parse ``argv`` (``sys.argv[1:]`` by default), spin."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        drivers = parse(_own_arguments(prog, argv))
    except DriverStartError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    return spin_drivers(prog, drivers, argv)


def run_driver(prog: str, parse: Callable[[list[str]], Driver], argv: Sequence[str] | None = None) -> int:
    """The ``main`` of a one-driver executable (:func:`run_drivers`)."""
    return run_drivers(prog, lambda args: [parse(args)], argv)


def spin_drivers(prog: str, drivers: Sequence[Driver], argv: Sequence[str]) -> int:
    """Build every driver's node in one rclpy context and spin each on an executor and thread of its
    own until SIGINT/SIGTERM or a callback raises; then shut every node down.

    ``argv`` carries the ROS arguments (``--ros-args -p use_sim_time:=true`` applies to every node).
    The process's Python log records go to ``/rosout`` through the first node
    (``tlt_common.ros.rosout_logging``; the record's logger name says which module logged it).
    Returns 0 after a clean shutdown, 1 when a node's callback raised, 2 when a node cannot start.
    """
    share_the_interpreter_quickly()  # each node's serial reader and executor thread share it
    init_rclpy([prog, *argv])
    nodes: list[tuple[str, Node]] = []
    logs: RosoutHandler | None = None
    code = 0
    try:
        for driver in drivers:
            nodes.append((driver.name, driver.build()))
            if logs is None:
                logs = forward_logging_to_rosout(nodes[0][1])
    except (ConfigError, DriverStartError) as exc:  # a file or device the node opens while building
        print(f"{prog}: {exc}", file=sys.stderr)
        code = 2
    else:
        code = 1 if _spin_each(nodes) else 0
    finally:
        _shut_down(prog, nodes, code, logs)
    return code


def _spin_each(nodes: list[tuple[str, Node]]) -> list[str]:
    """Spin every node on its own thread until the context shuts down or one of them raises; return
    the names of the nodes that raised. The context is shut down when it returns."""
    done = threading.Event()
    failed: list[str] = []

    def spin(name: str, executor: DirectExecutor) -> None:
        try:
            executor.spin()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except Exception:
            if rclpy.ok():
                failed.append(name)
                print(
                    f"driver {name} stopped on an error:\n{traceback.format_exc()}",
                    file=sys.stderr,
                    flush=True,
                )
            # else: SIGINT/SIGTERM shut the context down while a callback was publishing: a normal stop.
        finally:
            done.set()

    spinning = []
    for name, node in nodes:
        executor = DirectExecutor()
        executor.add_node(node)
        thread = threading.Thread(target=spin, args=(name, executor), name=f"spin-{name}", daemon=True)
        thread.start()
        spinning.append(thread)
    try:
        while not done.wait(0.5):  # polled: the main thread stays free for rclpy's signal handlers
            pass
    except KeyboardInterrupt:
        pass
    # Ends the other spins as a signal does: the nodes then shut down as after SIGTERM.
    _end_context()
    deadline = time.monotonic() + SHUTDOWN_TIMEOUT_S
    for thread in spinning:
        thread.join(max(0.0, deadline - time.monotonic()))
    return failed


def _shut_down(prog: str, nodes: list[tuple[str, Node]], code: int, logs: RosoutHandler | None) -> None:
    """Each node's ``shutdown`` (stop its loop, release its link), at once on threads of their own,
    then stop publishing the log records and destroy the nodes; exits the process with ``code`` if
    one is still hanging after the bound."""
    pending = {name for name, _ in nodes}

    def shut(name: str, node: Node) -> None:
        try:
            stop = getattr(node, "shutdown", None)
            if stop is not None:
                stop()
        except Exception:
            print(f"{prog}: {name} did not shut down cleanly:\n{traceback.format_exc()}", file=sys.stderr)
        finally:
            pending.discard(name)

    threads = [threading.Thread(target=shut, args=item, daemon=True) for item in nodes]
    for thread in threads:
        thread.start()
    deadline = time.monotonic() + SHUTDOWN_TIMEOUT_S
    for thread in threads:
        thread.join(max(0.0, deadline - time.monotonic()))
    if pending:
        print(
            f"{prog}: {', '.join(sorted(pending))} still shutting down after {SHUTDOWN_TIMEOUT_S:g} s; "
            "exiting without them",
            file=sys.stderr,
            flush=True,
        )
        os._exit(code)
    if logs is not None:
        logs.remove()
    for _, node in nodes:
        node.destroy_node()
    _end_context()


def _end_context() -> None:
    try:
        rclpy.try_shutdown()
    except RuntimeError:  # rclpy's signal handler shut it down between try_shutdown's test and its call
        pass


__all__ = [
    "HARDWARE_CONFIG_DIR",
    "SHUTDOWN_TIMEOUT_S",
    "Driver",
    "DriverStartError",
    "chain_driver",
    "run_driver",
    "run_drivers",
    "spin_drivers",
]
