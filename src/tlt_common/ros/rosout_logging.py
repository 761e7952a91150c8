"""Python ``logging`` of a node's process on ``/rosout``, at the level the process is given.

rclpy publishes on ``/rosout`` only what goes through a node's rcutils logger
(``node.get_logger()``); the project's modules (the behaviour trees, the CRS, vision, the drivers,
the twin) log with Python's ``logging``, which rclpy never sees, so none of it reached ``/rosout``
or a run's MCAP recording. :func:`forward_logging_to_rosout`, called once by each process after it
has created its node, puts a :class:`RosoutHandler` on the root logger: every record that passes the
process's level is published on ``/rosout`` as an ``rcl_interfaces/msg/Log``, as rcl publishes a
node's own messages (same QoS), named ``<node logger>.<Python logger>`` (``crs.tlt_crs``), with the
record's severity, time, file, function and line. The console handlers the process configured stay
as they are, so its console output does not change.

Levels: the process's level is its node logger's, from ``--ros-args --log-level LEVEL`` (or
``--log-level <node>:=LEVEL``); the root Python logger is set to the same level, so ``logging`` and
``node.get_logger()`` agree. ``TLT_LOG_LEVEL`` (debug, info, warn, error or fatal) sets the default
level of every process that starts rclpy with :func:`init_rclpy`; a ``--log-level`` in the
process's own ROS arguments wins.

Records logged before the node exists, after the handler was removed, after the context shut
down, in a forked child, or while the handler itself publishes (rclpy or the middleware logging
from inside ``publish``) are left to the console handlers and not published.
"""

from __future__ import annotations

import logging
import os
import sys
import threading
from collections.abc import Mapping, Sequence
from typing import Any

import rclpy
import rclpy.logging
from rcl_interfaces.msg import Log
from rclpy._rclpy_pybind11 import InvalidHandle
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

LOG_LEVEL_ENV = "TLT_LOG_LEVEL"

#: The ``--log-level`` names rcutils takes, and the Python names that mean the same.
_LEVEL_NAMES = {
    "debug": "debug",
    "info": "info",
    "warn": "warn",
    "warning": "warn",
    "error": "error",
    "fatal": "fatal",
    "critical": "fatal",
}

#: rcl's own ``/rosout`` QoS (``rcl_qos_profile_rosout_default``): a recorder that starts late
#: still gets the last messages.
ROSOUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    lifespan=Duration(seconds=10),
)


class LogLevelError(ValueError):
    """``TLT_LOG_LEVEL`` names no level."""


def env_log_level(environ: Mapping[str, str] | None = None) -> str | None:
    """The level ``TLT_LOG_LEVEL`` names, as ``--log-level`` takes it; None when unset or empty.
    Raises :class:`LogLevelError` for a name that is no level."""
    value = (os.environ if environ is None else environ).get(LOG_LEVEL_ENV, "").strip()
    if not value:
        return None
    level = _LEVEL_NAMES.get(value.lower())
    if level is None:
        raise LogLevelError(
            f"{LOG_LEVEL_ENV}={value!r} is no log level (one of debug, info, warn, error, fatal)"
        )
    return level


def ros_args_with_env_level(args: Sequence[str], environ: Mapping[str, str] | None = None) -> list[str]:
    """``args`` for ``rclpy.init`` (the program name first) with ``TLT_LOG_LEVEL`` as the default
    ``--log-level``, placed before the process's own ROS arguments so that theirs wins.

    A bad ``TLT_LOG_LEVEL`` ends the process with a message and exit code 2, as a bad argument does.
    """
    try:
        level = env_log_level(environ)
    except LogLevelError as exc:
        prog = args[0] if args else "tlt"
        print(f"{prog}: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    if level is None:
        return list(args)
    return [args[0], "--ros-args", "--log-level", level, "--", *args[1:]]


def init_rclpy(args: Sequence[str], **kwargs: Any) -> None:
    """``rclpy.init(args=..., **kwargs)`` at the process's log level: ``TLT_LOG_LEVEL`` as the
    default ``--log-level`` (:func:`ros_args_with_env_level`), and the root Python logger at the
    default level rclpy now has, so that what the process logs while it builds its node is
    filtered as it will be after (:func:`forward_logging_to_rosout` then takes its node's level)."""
    rclpy.init(args=ros_args_with_env_level(args), **kwargs)
    logging.getLogger().setLevel(python_level(rclpy.logging.get_logger_level("")))


def python_level(severity: int) -> int:
    """The Python ``logging`` level of an rcutils severity (the numbers are the same; unset is
    rcutils' default, info)."""
    return int(severity) or logging.INFO


def _ros_level(levelno: int) -> int:
    """The ``Log`` level of a Python record: its own, or the highest below it for a custom level."""
    for level in (Log.FATAL, Log.ERROR, Log.WARN, Log.INFO):
        if levelno >= level:
            return level
    return Log.DEBUG


class RosoutHandler(logging.Handler):
    """Publishes the records it handles on ``/rosout`` through ``node`` (see the module docstring)."""

    def __init__(self, node: Node) -> None:
        super().__init__()
        self._node = node
        self._prefix = node.get_logger().name
        self._pid = os.getpid()
        self._inside = threading.local()
        self._publisher: Publisher | None = node.create_publisher(Log, "/rosout", ROSOUT_QOS)
        # The message text as a console shows it: the message, then any traceback and stack.
        self.setFormatter(logging.Formatter("%(message)s"))

    def emit(self, record: logging.LogRecord) -> None:
        publisher = self._publisher
        if publisher is None or os.getpid() != self._pid or getattr(self._inside, "busy", False):
            return
        self._inside.busy = True
        try:
            if not self._node.context.ok():
                return
            msg = Log()
            seconds = int(record.created)
            msg.stamp.sec = seconds
            msg.stamp.nanosec = min(int((record.created - seconds) * 1e9), 999_999_999)
            msg.level = _ros_level(record.levelno)
            msg.name = self._prefix if record.name == "root" else f"{self._prefix}.{record.name}"
            msg.msg = self.format(record)
            msg.file = record.pathname or ""
            msg.function = record.funcName or ""
            msg.line = max(0, int(record.lineno or 0))
            publisher.publish(msg)
        except InvalidHandle:  # the node was destroyed under the record: the console has it
            self._publisher = None
        except Exception:
            if self._node.context.ok():
                self.handleError(record)
            else:  # the context shut down under the record (a shutdown): the console has it
                self._publisher = None
        finally:
            self._inside.busy = False

    def remove(self) -> None:
        """Stop publishing and leave the root logger; call before the node is destroyed."""
        logging.getLogger().removeHandler(self)
        publisher, self._publisher = self._publisher, None
        if publisher is not None:
            try:
                self._node.destroy_publisher(publisher)
            except Exception:  # the node or its context is gone already, and the publisher with it
                pass
        self.close()


def forward_logging_to_rosout(node: Node) -> RosoutHandler:
    """Publish the process's Python log records on ``/rosout`` through ``node``, and set the root
    logger's level to the node logger's (``--log-level``). Call once per process, after the node
    exists; call :meth:`RosoutHandler.remove` on the result before destroying the node."""
    logging.getLogger().setLevel(python_level(node.get_logger().get_effective_level()))
    handler = RosoutHandler(node)
    logging.getLogger().addHandler(handler)
    return handler


__all__ = [
    "LOG_LEVEL_ENV",
    "ROSOUT_QOS",
    "LogLevelError",
    "RosoutHandler",
    "env_log_level",
    "forward_logging_to_rosout",
    "init_rclpy",
    "python_level",
    "ros_args_with_env_level",
]
