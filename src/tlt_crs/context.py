"""What every CRS behaviour shares: the node, the mission and tower model, clocks, sensors, events.

One :class:`CrsContext` is built per CRS node (or per test) and handed to the subtree builders of
:mod:`tlt_crs.tree`. It holds no behaviour logic of its own beyond small accessors:

* ``clock`` is *mission time*: ROS time (so ``use_sim_time`` applies) that stands still while the
  CRS is paused, so a pause never makes a timeout expire on resume;
* ``cache`` holds the sensor topics (its ages are plain ROS time: a stale sensor is stale even
  when paused);
* ``board`` reads and writes the py_trees blackboard keys of ``config/crs/writable_blackboard.yaml``;
* ``event`` publishes ``tlt_interfaces/Event`` on ``/events``, logs it and tells each of
  ``event_listeners`` (the ground bridge adds the ground link's sender).
"""

from __future__ import annotations

import enum
import logging
import threading
from collections.abc import Callable
from typing import Any

import py_trees
from rclpy.node import Node

from tlt_common import ros_names
from tlt_common.bt.ros import TopicCache, node_clock
from tlt_common.bt.writable_blackboard import WritableBlackboard
from tlt_common.mission.schema import Mission
from tlt_common.mission.tower_model import TowerModel
from tlt_crs.config import CrsConfig
from tlt_crs.index_record import IndexRecord
from tlt_crs.inspection_desk import InspectionDesk

_log = logging.getLogger("tlt_crs")


class RunState(enum.IntEnum):
    """``tlt_interfaces/MissionProgress.run_state``."""

    IDLE = 0
    RUNNING = 1
    PAUSED = 2
    FAULT = 3
    STOPPED = 4
    DONE = 5


class MissionClock:
    """Seconds of ROS time minus the time spent held: paused from the ground, or held by the CRS
    itself while a device link is down. Each hold has a reason; the clock runs when none is left."""

    GROUND = "ground"  # the operator's Pause

    def __init__(self, ros_seconds: Callable[[], float]) -> None:
        self._now = ros_seconds
        self._paused_at: float | None = None
        self._paused_total = 0.0
        self._tick_time: float | None = None
        self._holds: set[str] = set()

    def __call__(self) -> float:
        if self._paused_at is not None:
            now = self._paused_at
        elif self._tick_time is not None:
            now = self._tick_time
        else:
            now = self._now()
        return now - self._paused_total

    def begin_tick(self) -> None:
        """Read ROS time once for the coming tick: every behaviour of a tick sees the same time,
        and the clock is not read (a ROS call) once per waiting behaviour."""
        self._tick_time = self._now()

    def end_tick(self) -> None:
        self._tick_time = None

    @property
    def paused(self) -> bool:
        """Paused by the operator."""
        return self.GROUND in self._holds

    @property
    def held(self) -> bool:
        """Stopped for any reason (the build waits)."""
        return self._paused_at is not None

    def pause(self, reason: str = GROUND) -> None:
        if self._paused_at is None:
            self._paused_at = self._now() if self._tick_time is None else self._tick_time
        self._holds.add(reason)

    def resume(self, reason: str = GROUND) -> None:
        self._holds.discard(reason)
        if self._paused_at is not None and not self._holds:
            self._paused_total += max(0.0, self._now() - self._paused_at)
            self._paused_at = None


class Board:
    """Direct access to top-level keys of the py_trees blackboard (the CRS's runtime model)."""

    def __init__(self, namespace: str = "") -> None:
        self.prefix = f"/{namespace.strip('/')}/" if namespace.strip("/") else "/"

    def get(self, key: str, default: Any = None) -> Any:
        return py_trees.blackboard.Blackboard.storage.get(self.prefix + key, default)

    def set(self, key: str, value: Any) -> None:
        py_trees.blackboard.Blackboard.set(self.prefix + key, value)


class CrsContext:
    """Shared state of one CRS: see the module docstring."""

    def __init__(
        self,
        node: Node,
        config: CrsConfig,
        mission: Mission,
        model: TowerModel,
        registry: WritableBlackboard,
        *,
        index: IndexRecord | None = None,
        ros_seconds: Callable[[], float] | None = None,
    ) -> None:
        from tlt_interfaces.msg import Event

        self.node = node
        self.config = config
        self.mission = mission
        self.model = model
        self.registry = registry
        self.index = index if index is not None else IndexRecord(mission, None)
        self.ros_seconds = ros_seconds or node_clock(node)
        self.clock = MissionClock(self.ros_seconds)
        self.cache = TopicCache(node, self.ros_seconds)
        self.board = Board(registry.namespace)
        self.desk = InspectionDesk()
        self.stopped = False
        self.link_fault = ""  # why the build is held for a device link (clears itself: LifterLinkWatch)
        # Held by the tick and by service callbacks that touch the blackboard or the model.
        self.lock = threading.RLock()
        self._event_pub = node.create_publisher(Event, ros_names.EVENTS, 50)
        self._event_type = Event
        # Told of every event after it is published: (severity, code, text).
        self.event_listeners: list[Callable[[int, str, str], None]] = []
        from tlt_interfaces.msg import GripperState, LifterState

        self._hardware_topics = {
            ros_names.LIFTER: (ros_names.state_topic(ros_names.LIFTER), LifterState),
            ros_names.TOP_GRIPPERS: (ros_names.state_topic(ros_names.TOP_GRIPPERS), GripperState),
            ros_names.ACTIVE_GRIPPERS: (ros_names.state_topic(ros_names.ACTIVE_GRIPPERS), GripperState),
        }
        for topic, msg_type in self._hardware_topics.values():
            self.cache.watch(topic, msg_type)
        from sensor_msgs.msg import JointState
        from tlt_interfaces.msg import EndEffectorState, HardwareStatus

        # Each ARS's end effector and arm, which the ARS cannot work without: read for Start only
        # (the ARS itself waits on them mid-build), and by the ground bridge for housekeeping.
        for ars in ros_names.ARS_AGENTS:
            ee, ur = ros_names.ee(ars), ros_names.ur(ars)
            self.cache.watch(ros_names.state_topic(ee), EndEffectorState)
            self.cache.watch(ros_names.joint_states_topic(ur), JointState)
            self.cache.watch(ros_names.hardware_status_topic(ur), HardwareStatus)
        self._arm_active = HardwareStatus.LIFECYCLE_ACTIVE
        self._servers = self._build_server_checks()
        from diagnostic_msgs.msg import DiagnosticStatus

        from tlt_common.ros.readiness import LATCHED, ReadinessWatch

        # Vision's services may be up before it has heard the joint states that place its cameras.
        self.cache.watch(ros_names.VISION_STATUS, DiagnosticStatus, LATCHED)
        # Every word vision says: an inspection lost with a restarted vision is asked again.
        self.vision_status = ReadinessWatch(node, ros_names.VISION_STATUS)

    def device_topics(self) -> list[str]:
        """The state topics of the lifter and the grippers, which the tree cannot build without."""
        return [topic for topic, _ in self._hardware_topics.values()]

    def _build_server_checks(self) -> list[tuple[str, Callable[[], bool]]]:
        """(what, is it up) for every server the CRS calls in a build: each ARS's ground command
        service and action servers, and vision's inspection services (the vision node offers the
        ARSs' tag and alignment services along with them). The clients are the ones the tree
        shares, made here on the node's thread rather than in a service callback."""
        from tlt_interfaces.action import AddCrossFrame, AddMember, AffixMember, FoundationRivet
        from tlt_interfaces.srv import GroundCommand, InspectBay, InspectPart

        from tlt_common.bt.ros import shared_action_client, shared_service_client

        actions = dict(
            zip(ros_names.ARS_ACTIONS, (AddCrossFrame, AddMember, AffixMember, FoundationRivet), strict=True)
        )
        node = self.node
        checks: list[tuple[str, Callable[[], bool]]] = []
        for ars in ros_names.ARS_AGENTS:
            name = ros_names.ground_command_service(ars)
            client = shared_service_client(node, GroundCommand, name)
            checks.append((f"{ars}: {name}", client.service_is_ready))
            for request, action_type in actions.items():
                name = ros_names.ars_action(ars, request)
                action = shared_action_client(node, action_type, name)
                checks.append((f"{ars}: {name}", action.server_is_ready))
        for srv_type, name in (
            (InspectPart, ros_names.VISION_INSPECT_PART),
            (InspectBay, ros_names.VISION_INSPECT_BAY),
        ):
            checks.append((f"vision: {name}", shared_service_client(node, srv_type, name).service_is_ready))
        return checks

    def not_ready(self) -> str:
        """Why a build cannot start now ('' when it can): a CRS driver whose state is missing or
        older than ``timeouts.sensor_max_age_s``, a lifter whose link is down, an ARS's end
        effector or arm not ready (:meth:`ars_hardware_not_ready`), an ARS or vision server not
        up yet, or vision not ready (:meth:`vision_not_ready`). Start is refused while this says
        anything."""
        return "; ".join(
            filter(
                None,
                (
                    self.hardware_not_ready(),
                    self.ars_hardware_not_ready(),
                    self._servers_not_up(),
                    self.vision_not_ready(),
                ),
            )
        )

    def vision_call_options(self) -> dict[str, Any]:
        """The limits of an inspection asked of vision (a ``ServiceCall``'s keywords), and how it is
        asked again when vision was restarted with it: once the new vision says ready, up to
        ``vision_retries`` times, each waiting up to ``timeouts.vision_back_s``."""
        timeouts = self.config.timeouts
        return {
            "service_timeout": timeouts.service_s,
            "timeout": timeouts.vision_s,
            "clock": self.clock,
            "retries": self.config.vision_retries,
            "server_state": self.vision_status,
            "back_within": timeouts.vision_back_s,
        }

    def vision_not_ready(self) -> str:
        """Why vision cannot answer yet ('' when it can), as its latched status says: it cannot
        place a camera before it has heard that camera's joint states, which the CRS may have heard
        already (each subscription is matched to the drivers on its own)."""
        from tlt_common.ros.readiness import not_ready_reason

        entry = self.cache.latest(ros_names.VISION_STATUS)
        why = not_ready_reason(None if entry is None else entry[0])
        return f"vision: {why}" if why else ""

    def ars_hardware_not_ready(self) -> str:
        """Why an ARS's end effector or arm cannot be trusted to build now ('' when they can): a
        state missing or older than ``timeouts.sensor_max_age_s``, an end effector not calibrated
        yet (its driver refuses every motion until the width joint is zeroed on its limit switch)
        or faulted, an arm whose driver says it is not active."""
        troubles = []
        for ars in ros_names.ARS_AGENTS:
            for name, trouble in (
                (ros_names.ee(ars), self._end_effector_trouble),
                (ros_names.ur(ars), self._arm_trouble),
            ):
                if why := trouble(name):
                    troubles.append(f"{name}: {why}")
        return "; ".join(troubles)

    def _end_effector_trouble(self, ee: str) -> str:
        topic = ros_names.state_topic(ee)
        if why := self._state_trouble(topic):
            return why
        entry = self.cache.latest(topic)
        assert entry is not None  # _state_trouble found it
        state = entry[0]
        if state.fault:
            return f"fault ({state.fault_reason or 'no reason'})"
        return "" if state.calibrated else "width joint not calibrated yet"

    def _arm_trouble(self, ur: str) -> str:
        if why := self._state_trouble(ros_names.joint_states_topic(ur)):
            return why
        # Twice a second, against 50 Hz joint states: those say whether the driver is up.
        entry = self.cache.latest(ros_names.hardware_status_topic(ur))
        if entry is None or entry[0].lifecycle_state == self._arm_active:
            return ""
        status = entry[0]
        return f"arm not active ({status.fault or f'lifecycle state {status.lifecycle_state}'})"

    def _servers_not_up(self) -> str:
        down = [what for what, is_up in self._servers if not is_up()]
        if len(down) > 3:
            return f"{', '.join(down[:3])} and {len(down) - 3} more not up"
        return f"{', '.join(down)} not up" if down else ""

    def lifter_link_down(self) -> str:
        """Why the lifter cannot be reached now ('' when it can): see :meth:`device_trouble`."""
        why = self.device_trouble(ros_names.LIFTER)
        return f"lifter {why}" if why else ""

    def hardware_not_ready(self) -> str:
        """Why the CRS's own mechanisms cannot be trusted to build now ('' when they can), each
        driver's :meth:`device_trouble` named."""
        troubles = ((name, self.device_trouble(name)) for name in self._hardware_topics)
        return "; ".join(f"{name}: {why}" for name, why in troubles if why)

    def device_trouble(self, name: str) -> str:
        """Why driver ``name``'s state cannot be trusted now ('' when it can): none yet, one older
        than ``timeouts.sensor_max_age_s``, or (the lifter) the driver reporting its link down."""
        topic = self._hardware_topics[name][0]
        why = self._state_trouble(topic)
        if not why and name == ros_names.LIFTER:
            entry = self.cache.latest(topic)
            assert entry is not None  # _state_trouble found it
            state = entry[0]
            if not state.link_ok:
                return f"link down ({state.fault or 'no reason'})"
        return why

    def _state_trouble(self, topic: str) -> str:
        """'has no state yet' or 'state ... s old' for a state topic not fresh, else ''."""
        age = self.cache.age(topic)
        if age is None:
            return "has no state yet"
        if age > self.config.timeouts.sensor_max_age_s:
            return f"state {age:.1f} s old"
        return ""

    # ----- blackboard -----
    @property
    def fault(self) -> str:
        return self.board.get("fault", "") or ""

    def raise_fault(self, reason: str) -> None:
        self.board.set("fault", reason)
        self.event(3, "CRS_FAULT", reason)

    @property
    def started(self) -> bool:
        return bool(self.board.get("started", False))

    @property
    def paused(self) -> bool:
        return self.clock.paused

    @property
    def run_state(self) -> RunState:
        """Derived from the blackboard, the clock and the model, so it can never disagree with them."""
        if self.stopped:
            return RunState.STOPPED
        if self.link_fault:
            return RunState.FAULT
        if self.paused:
            return RunState.PAUSED
        if self.fault:
            return RunState.FAULT
        if self.model.tower_built:
            return RunState.DONE
        return RunState.RUNNING if self.started else RunState.IDLE

    # ----- events -----
    def event(self, severity: int, code: str, text: str) -> None:
        msg = self._event_type()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.source = self.node.get_name()
        msg.severity = severity
        msg.code = code
        msg.text = text
        self._event_pub.publish(msg)
        level = {0: logging.DEBUG, 1: logging.INFO, 2: logging.WARNING}.get(severity, logging.ERROR)
        _log.log(level, "[%s] %s", code, text)
        for listener in self.event_listeners:
            try:
                listener(severity, code, text)
            except Exception as exc:  # the ROS event went out; a listener's fault is not the tree's
                _log.warning("event %s not passed on: %s", code, exc)


__all__ = ["Board", "CrsContext", "MissionClock", "RunState"]
