"""Python ``logging`` records on ``/rosout``, at the process's level: a real node with the handler,
a second node listening on ``/rosout``; and ``TLT_LOG_LEVEL`` as the processes' default level."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator

import pytest
import rclpy
import rclpy.logging
from rcl_interfaces.msg import Log
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from tlt_common.ros.rosout_logging import (
    LOG_LEVEL_ENV,
    ROSOUT_QOS,
    env_log_level,
    forward_logging_to_rosout,
    init_rclpy,
    ros_args_with_env_level,
)


@pytest.fixture
def root_logger() -> Iterator[logging.Logger]:
    """The root logger without the handlers earlier tests left on it (a ``basicConfig`` of a
    ``main()`` run under capture writes to a stream since closed), its level and handlers put
    back after the test."""
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    root.handlers[:] = []
    yield root
    root.setLevel(level)
    root.handlers[:] = handlers


@pytest.fixture
def default_ros_level() -> Iterator[None]:
    """rcutils' default level (process-wide) put back to info after the test."""
    yield
    rclpy.logging.set_logger_level("", rclpy.logging.LoggingSeverity.INFO)


class Rosout:
    """A node with the handler installed and a listener node on ``/rosout``, in one context."""

    def __init__(self, name: str, ros_args: list[str]) -> None:
        self.context = rclpy.Context()
        rclpy.init(args=["test", "--ros-args", *ros_args], context=self.context)
        self.node = Node(name, context=self.context)
        self.listener = Node(f"{name}_listener", context=self.context)
        self.got: list[Log] = []
        self.listener.create_subscription(Log, "/rosout", self.got.append, ROSOUT_QOS)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.listener)
        self.handler = forward_logging_to_rosout(self.node)

    def mine(self) -> list[Log]:
        return [m for m in self.got if m.name.startswith(f"{self.node.get_name()}.")]

    def spin_until(self, count: int, timeout_s: float = 10.0) -> list[Log]:
        deadline = time.monotonic() + timeout_s
        while len(self.mine()) < count and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return self.mine()

    def close(self) -> None:
        self.handler.remove()
        self.executor.shutdown()
        self.listener.destroy_node()
        self.node.destroy_node()
        self.context.try_shutdown()


def test_a_python_warning_reaches_rosout_and_a_debug_record_below_the_level_does_not(root_logger):
    ros = Rosout("rosout_logging_info", ["--log-level", "rosout_logging_info:=info"])
    try:
        assert root_logger.level == logging.INFO
        logging.getLogger("tlt_crs.x").debug("not at info")
        logging.getLogger("tlt_crs.x").warning("beam %d is %s", 3, "late")
        (msg,) = ros.spin_until(1)
        assert msg.level == Log.WARN
        assert msg.name == "rosout_logging_info.tlt_crs.x"
        assert msg.msg == "beam 3 is late"
        assert (
            msg.function == "test_a_python_warning_reaches_rosout_and_a_debug_record_below_the_level_does_not"
        )
        assert msg.file == __file__ and msg.line > 0
        assert abs(msg.stamp.sec + msg.stamp.nanosec * 1e-9 - time.time()) < 30.0
        # Published after the warning, so it would have come by now: nothing below info came.
        logging.getLogger("tlt_crs.x").info("last")
        assert [m.msg for m in ros.spin_until(2)] == ["beam 3 is late", "last"]
    finally:
        ros.close()


def test_the_log_level_argument_sets_the_python_level_too(root_logger):
    ros = Rosout("rosout_logging_debug", ["--log-level", "rosout_logging_debug:=debug"])
    try:
        assert root_logger.level == logging.DEBUG
        try:
            raise ValueError("no bay")
        except ValueError:
            logging.getLogger("tlt_vision").exception("inspection failed")
        logging.getLogger("tlt_vision").debug("detail")
        first, second = ros.spin_until(2)
        assert (first.level, second.level) == (Log.ERROR, Log.DEBUG)
        assert first.msg.startswith("inspection failed\nTraceback") and "ValueError: no bay" in first.msg
        assert second.msg == "detail"
    finally:
        ros.close()


def test_nothing_is_published_once_removed_or_after_the_node_is_gone(root_logger, capsys):
    ros = Rosout("rosout_logging_gone", ["--log-level", "rosout_logging_gone:=info"])
    try:
        ros.handler.remove()
        assert ros.handler not in root_logger.handlers
        logging.getLogger("tlt_crs").warning("after removal")
        ros.spin_until(1, timeout_s=1.0)
        assert ros.mine() == []
        # A handler left installed past the node's end drops its records without an error.
        late = forward_logging_to_rosout(ros.node)
        ros.node.destroy_node()
        logging.getLogger("tlt_crs").warning("after destruction")
        ros.context.try_shutdown()
        logging.getLogger("tlt_crs").warning("after shutdown")
        late.remove()
        assert "Logging error" not in capsys.readouterr().err
    finally:
        ros.close()


def test_tlt_log_level_is_the_default_and_a_log_level_argument_wins(
    monkeypatch, default_ros_level, root_logger
):
    monkeypatch.delenv(LOG_LEVEL_ENV, raising=False)
    assert ros_args_with_env_level(["tlt-crs", "--ros-args", "-p", "a:=1"]) == [
        "tlt-crs",
        "--ros-args",
        "-p",
        "a:=1",
    ]
    monkeypatch.setenv(LOG_LEVEL_ENV, "WARNING")
    assert env_log_level() == "warn"
    own = ["tlt-crs", "--ros-args", "--log-level", "tlt_env_named:=error"]
    assert ros_args_with_env_level(own)[:5] == ["tlt-crs", "--ros-args", "--log-level", "warn", "--"]
    context = rclpy.Context()
    init_rclpy(own, context=context)
    try:
        assert rclpy.logging.get_logger_effective_level("tlt_env_other") == rclpy.logging.LoggingSeverity.WARN
        assert (
            rclpy.logging.get_logger_effective_level("tlt_env_named") == rclpy.logging.LoggingSeverity.ERROR
        )
        assert root_logger.level == logging.WARNING  # before any node exists
    finally:
        context.try_shutdown()
    monkeypatch.setenv(LOG_LEVEL_ENV, "error")
    context = rclpy.Context()
    init_rclpy(["tlt-crs", "--ros-args", "--log-level", "debug"], context=context)
    try:
        assert (
            rclpy.logging.get_logger_effective_level("tlt_env_other") == rclpy.logging.LoggingSeverity.DEBUG
        )
        assert root_logger.level == logging.DEBUG
    finally:
        context.try_shutdown()


def test_a_bad_tlt_log_level_is_refused(capsys):
    with pytest.raises(SystemExit) as exit_:
        ros_args_with_env_level(["tlt-ars"], {LOG_LEVEL_ENV: "loud"})
    assert exit_.value.code == 2
    assert "tlt-ars: TLT_LOG_LEVEL='loud' is no log level" in capsys.readouterr().err
