"""The CRS process (paper §IV.B, §V.C.2): ticks the CRS tree on ROS time and serves the ground and ARSs.

``tlt-crs [--config config/crs/crs.yaml] [--mission M] [--state-file F] [--autostart] [--ros-args ...]``

* Ticks the tree at ``tick_rate_hz`` on a timer of the node's clock (ROS time, so
  ``--ros-args -p use_sim_time:=true`` runs it on the twin's ``/clock``).
* Publishes ``/crs/tree_status`` (``TreeStatus``) at ``status_rate_hz`` (after a tick), with each
  shape's definition on ``/crs/tree_definition`` before its first status,
  ``/crs/mission_progress`` (``MissionProgress``) at ``progress_rate_hz`` and after every tower
  model change, and ``/events``.
* Serves ``/crs/set_blackboard_value`` (the writable registry decides) and ``/crs/inspect_part``
  (the ARS's part inspection; see :mod:`tlt_crs.behaviours.inspection`).
* Takes ground commands through :attr:`CrsNode.commands` (see :mod:`tlt_crs.commands`):
  ``submit(name, params, on_ack)`` in process (``--autostart``, tests), and with ``--ground-link``
  over CCSDS (:mod:`tlt_crs.ground_bridge`, which checks each command on arrival and queues it).
* Pause holds the build (running lifter/gripper/camera goals are canceled so the actuators hold;
  ARS goals keep their place and the ARSs get PAUSE); Resume continues; Stop cancels the work, puts
  the lifter in Safe, forwards STOP and ends the process with status 0.

The tower model is resumed from ``state_file`` at start-up: a CRS killed mid-bay carries on where
the model stands and never requests a member the model says is placed. A malformed configuration,
mission or state file is refused with its reason (exit status 2) before anything moves.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import py_trees
import rclpy
from py_trees.common import Status
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions

from tlt_common import ros_names
from tlt_common.bt.ros import TreeStatusPublisher
from tlt_common.bt.status_codec import TreeShape
from tlt_common.bt.writable_blackboard import WritableBlackboard
from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import Mission, load_mission
from tlt_common.mission.tower_model import TowerModel, TowerModelError
from tlt_common.ros.direct_executor import DirectMultiThreadedExecutor
from tlt_common.ros.executor_stop import stop_executor
from tlt_common.ros.interpreter_lock import share_the_interpreter_quickly
from tlt_common.ros.lean_node import LeanNode
from tlt_common.ros.periodic_timer import create_periodic_timer
from tlt_common.ros.rosout_logging import forward_logging_to_rosout, init_rclpy
from tlt_common.ros.sim_clock_watch import watch_sim_clock
from tlt_common.ros.stop_signals import stop_on_signals
from tlt_common.ros.topic_silence_watch import TopicSilenceWatch
from tlt_crs.behaviours.inspection import serve_inspect_part
from tlt_crs.commands import CommandProcessor, CommandQueue
from tlt_crs.config import REPO_CONFIG, CrsConfig, load_config
from tlt_crs.context import CrsContext
from tlt_crs.index_record import IndexRecord
from tlt_crs.tree import build_crs_tree

LINK_CONFIG = Path(__file__).resolve().parents[2] / "config" / "ccsds" / "link.yaml"

_log = logging.getLogger("tlt_crs")


class CrsNode(LeanNode):
    """The CRS node around one context and tree (built from ``config`` and ``mission``)."""

    def __init__(
        self,
        config: CrsConfig,
        mission: Mission,
        model: TowerModel,
        registry: WritableBlackboard,
        index: IndexRecord,
        *,
        node_name: str = "crs",
        **node_kwargs: Any,
    ) -> None:
        super().__init__(node_name, **node_kwargs)
        from tlt_interfaces.msg import MissionProgress
        from tlt_interfaces.srv import SetBlackboardValue

        self.ctx = CrsContext(self, config, mission, model, registry, index=index)
        self.finished = False
        self._interrupt = False
        # What a command does to the node: the callbacks read the tree only when a command runs.
        self.processor = CommandProcessor(
            self.ctx, hold=self._hold_motions, stop_tree=self._request_interrupt, on_stopped=self._stopped
        )
        self.commands: CommandQueue = self.processor.queue
        self.root = build_crs_tree(self.ctx, self.processor)
        # The root is ticked directly: py_trees' BehaviourTree.tick walks every node after each tick
        # for its visitors (milliseconds for a 10-bay tree), which the guards are there to avoid.
        self.tick_count = 0
        self.shape = TreeShape.of(self.root)
        self.status_publisher = TreeStatusPublisher(
            self,
            "crs",
            topic=ros_names.tree_status_topic("crs"),
            definition_topic=ros_names.tree_definition_topic("crs"),
            period_s=1.0 / config.status_rate_hz,
        )
        # Called at the end of each tick, under the context's lock (the ground bridge notes steps).
        self.tick_listeners: list[Callable[[], None]] = []
        self._model_changed = False
        model.listeners.append(self._on_model_change)

        self._progress_type = MissionProgress
        self._progress_pub = self.create_publisher(MissionProgress, ros_names.CRS_MISSION_PROGRESS, 10)
        # Ticks never overlap; the clients they use are safe across threads (SerialisedActionClient).
        tick_group = MutuallyExclusiveCallbackGroup()
        self._service_group = ReentrantCallbackGroup()
        self.create_service(
            SetBlackboardValue,
            ros_names.CRS_SET_BLACKBOARD,
            self._on_set_blackboard,
            callback_group=self._service_group,
        )
        serve_inspect_part(self.ctx, self._service_group)
        # On the steady clock on hardware: a system clock set back must not stop the tree and its
        # reports (tlt_common.ros.periodic_timer); the tree's own timeouts stay on mission time.
        create_periodic_timer(self, 1.0 / config.tick_rate_hz, self.tick, callback_group=tick_group)
        create_periodic_timer(
            self, 1.0 / config.progress_rate_hz, self.publish_progress, callback_group=tick_group
        )
        self.ctx.event(
            1, "CRS_UP", f"mission '{mission.name}': {model.bays_built()}/{mission.bay_count} bay(s) built"
        )

    # ----- ticking -----
    def tick(self) -> None:
        """One tick of the tree, then the asynchronous commands; never raises."""
        if self.finished:
            return
        with self.ctx.lock:
            self.ctx.clock.begin_tick()
            try:
                for _ in self.root.tick():
                    pass
            except Exception as exc:  # a behaviour bug becomes a fault with its reason, not a dead CRS
                _log.exception("tick failed")
                self.interrupt()
                self.ctx.raise_fault(f"internal error in the CRS tree: {exc!r}")
            finally:
                self.ctx.clock.end_tick()
            self.tick_count += 1
            if self._interrupt:
                self._interrupt = False
                self.interrupt()
            self.processor.poll()
            for listener in self.tick_listeners:
                try:
                    listener()
                except Exception:  # a listener's bug must not stop the build
                    _log.exception("tick listener failed")
            self.status_publisher.publish_due(self.shape, self.tick_count)
        if self._model_changed:
            self._model_changed = False
            self.publish_progress()

    def interrupt(self) -> None:
        """Stop every running behaviour (goals in flight are canceled)."""
        self.root.stop(Status.INVALID)

    def _hold_motions(self) -> None:
        for behaviour in self.root.iterate():
            if getattr(behaviour, "hold_on_pause", False) and behaviour.status == Status.RUNNING:
                behaviour.stop(Status.INVALID)

    def _request_interrupt(self) -> None:
        self._interrupt = True

    def _stopped(self) -> None:
        self.finished = True

    def _on_model_change(self, model: TowerModel) -> None:
        self.ctx.board.set("tower_built", model.tower_built)
        self._model_changed = True

    # ----- telemetry -----
    def current_step(self) -> str:
        tip = self.root.tip()
        return tip.name if tip is not None and self.root.status == Status.RUNNING else ""

    def progress(self) -> Any:
        msg = self._progress_type()
        msg.header.stamp = self.get_clock().now().to_msg()
        ctx = self.ctx
        with ctx.model.lock:
            ctx.model.fill_progress(msg)
        msg.current_bay = int(ctx.board.get("current_bay", 0) or 0)
        msg.current_step = self.current_step()
        msg.run_state = int(ctx.run_state)
        msg.started = ctx.started
        msg.fault = ctx.fault or ctx.link_fault
        return msg

    def publish_progress(self) -> None:
        self._progress_pub.publish(self.progress())

    # ----- services -----
    def _on_set_blackboard(self, request: Any, response: Any) -> Any:
        with self.ctx.lock:
            result = self.ctx.registry.write_msg(request.key, request.value)
        response.accepted, response.reason = result.accepted, result.reason
        if result.accepted:
            self.ctx.event(1, "BLACKBOARD_SET", f"{request.key} set by service")
        return response


def build_node(config: CrsConfig, **node_kwargs: Any) -> CrsNode:
    """Load the mission, the tower model, the index record and the registry; build the node.

    Raises ``ConfigError`` (mission, registry) or ``TowerModelError`` (state files) with the reason.
    """
    mission = load_mission(config.mission)
    registry = WritableBlackboard.load(config.writable_blackboard)
    config.state_file.parent.mkdir(parents=True, exist_ok=True)
    model = TowerModel.open(mission, config.state_file)
    index = IndexRecord(mission, config.progress_file)
    return CrsNode(config, mission, model, registry, index, **node_kwargs)


# How long a stopped CRS keeps listening to its devices before it sends their last states home, s.
FINAL_STATES_S = 0.5


def _autostart_when_ready(node: CrsNode) -> None:
    """Submit Start as soon as the CRS would accept it: its drivers may still be coming up."""
    waiting: list[str] = []

    def attempt() -> None:
        reason = node.commands.check("start", {})
        if reason is not None and reason.startswith("not ready"):
            if not waiting:
                _log.info("autostart: waiting (%s)", reason)
            waiting.append(reason)
            return
        timer.cancel()
        node.destroy_timer(timer)
        node.commands.submit("start", {}, lambda stage, why: _log.info("autostart: %s %s", stage.label, why))

    # Wall time: under sim time nothing ticks before the twin's /clock does.
    timer = node.create_timer(0.5, attempt, clock=Clock(clock_type=ClockType.STEADY_TIME))


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args = []
    if "--ros-args" in argv:
        at = argv.index("--ros-args")
        argv, ros_args = argv[:at], argv[at:]
    parser = argparse.ArgumentParser(prog="tlt-crs", description="The Construction Robot System node.")
    parser.add_argument(
        "--config", type=Path, default=REPO_CONFIG, help="CRS configuration (default: %(default)s)"
    )
    parser.add_argument("--mission", type=Path, help="mission file (overrides the configuration)")
    parser.add_argument(
        "--state-file", type=Path, help="tower model state file (overrides the configuration)"
    )
    parser.add_argument(
        "--autostart", action="store_true", help="submit Start at start-up (unattended runs, tests)"
    )
    parser.add_argument(
        "--ground-link",
        type=Path,
        nargs="?",
        const=LINK_CONFIG,
        metavar="LINK_YAML",
        help="serve the CCSDS ground link (settings: %(const)s; key file from it or $TLT_GROUND_KEY_FILE)",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        config = load_config(args.config, mission=args.mission, state_file=args.state_file)
    except ConfigError as exc:
        print(f"tlt-crs: refused: {exc}", file=sys.stderr)
        return 2
    share_the_interpreter_quickly()  # the tick, the executor's threads and the ground link share it
    stop = stop_on_signals()
    init_rclpy(["tlt-crs", *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    py_trees.blackboard.Blackboard.clear()
    try:
        try:
            node = build_node(config)
        except (ConfigError, TowerModelError, OSError) as exc:
            print(f"tlt-crs: refused: {exc}", file=sys.stderr)
            return 2
        logs = forward_logging_to_rosout(node)
        bridge = None
        if args.ground_link is not None:
            from tlt_common.ccsds.auth import KeyFileError, ReplayStateError
            from tlt_common.ccsds.link_config import load_link_config
            from tlt_crs.ground_bridge import GroundBridge

            try:
                bridge = GroundBridge(node, load_link_config(args.ground_link))
            except (ConfigError, KeyFileError, ReplayStateError, OSError) as exc:
                print(f"tlt-crs: refused: ground link: {exc}", file=sys.stderr)
                logs.remove()
                node.destroy_node()
                return 2
            bridge.start()
            _log.info("ground link on %s:%d", *bridge.link.address)
        if args.autostart:
            _autostart_when_ready(node)
        executor = DirectMultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        clock_watch = watch_sim_clock(node)
        silence_watch = TopicSilenceWatch(node.ctx.cache, node.ctx.device_topics(), node.get_name()).start()
        try:
            while not stop and rclpy.ok() and not node.finished:
                executor.spin_once(timeout_sec=0.1)
            if node.finished and bridge is not None:
                # After a ground Stop: the devices' states that followed it (the lifter in Safe,
                # the arms standing) reach the ground before the process ends.
                deadline = time.monotonic() + FINAL_STATES_S
                while not stop and rclpy.ok() and time.monotonic() < deadline:
                    executor.spin_once(timeout_sec=0.05)
                bridge.send_housekeeping()
        except ExternalShutdownException:  # the context shut down by someone else
            pass
        finally:
            if clock_watch is not None:
                clock_watch.stop()
            silence_watch.stop()
            node.interrupt()
            node.ctx.desk.close("the CRS is stopping")
            if bridge is not None:
                bridge.close()
            # Callbacks still running when the node is destroyed use freed handles: give them
            # time to return first (the context is still valid: tlt_common.ros.stop_signals).
            for error in stop_executor(executor, 5.0):
                node.get_logger().warning(f"a callback ended with {error!r} at shutdown")
            logs.remove()
            node.destroy_node()
        return 0
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
