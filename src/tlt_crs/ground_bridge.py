"""The CCSDS ground link inside the CRS process: ground commands into the tree, telemetry out.

The bridge opens the link itself, handing it the CRS's command path. A command is validated once
when it arrives, on the link's receive thread: the link's packet checks (size, CRC,
authentication, replay, parameters), then the CRS's rules for its state (a Pause while not
started, a blackboard write outside the writable registry or an actuator command while building is
refused with the reason, and never acts). A refused command gets one *rejected* acknowledgement;
an accepted one gets one *accepted* acknowledgement and is queued for the tree, which validates it
again against the state it finds and executes it on its next tick (Fig. 13). The outcome goes back
as one *completed* or *failed* acknowledgement.

Telemetry, each packet at its rate in the definitions file: the CRS tree's encoded status
(``tree_status``, one packet per part; the ARSs' as their TreeStatus messages arrive), each
agent's tree definition (``tree_definition``, when the agent moves to a shape and again at its
rate: :mod:`tlt_crs.tree_definition_relay`; an ARS's from its ``tree_definition`` topic), mission
progress (``hk_mission``), the tower model (``hk_tower``), and housekeeping from the mechanisms'
state topics (``hk_lifter``, ``hk_grippers``, ``hk_ee``, ``hk_arm_joints``: a packet goes out once
its topic has been heard).

Every CRS event goes to the ground (the bridge is one of the context's event listeners), and a
``CRS_UP`` event when the bridge starts (a restarted CRS is seen as one).

``mission_step`` goes out whenever the tree's running leaf, the current bay or the run state
changes, with the CRS's ROS time: the ground's record of when each step of each member ran. The
change is noted at the end of every tick and sent from the telemetry timer, so a step that runs
for a single tick is still reported (sampled on a timer instead, a quick foundation rivet can go
unseen on a loaded machine).
"""

from __future__ import annotations

import functools
import logging
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import py_trees
from py_trees.common import Status
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

from tlt_common import ros_names
from tlt_common.bt.ros import TreeStatusPublisher
from tlt_common.bt.shape_definition import parse_document_json
from tlt_common.bt.status_codec import StatusCodecError, TreeShape, encode
from tlt_common.ccsds.reasons import AckStage, Reason, Severity
from tlt_common.mission.member_states import pack_member_states
from tlt_common.mission.tower_model import PLACED, RIVETED
from tlt_common.ros.periodic_timer import create_periodic_timer
from tlt_crs.commands import CommandQueue
from tlt_crs.context import CrsContext
from tlt_crs.ground_link.link import GroundCommand, GroundLink
from tlt_crs.tree_definition_relay import TreeDefinitionRelay

_log = logging.getLogger("tlt_crs.ground_bridge")
# Status bytes per tree_status packet: the definition allows 1024; 256 keeps packets small.
STATUS_BYTES_PER_PACKET = 256


class CrsTree(Protocol):
    """What the bridge uses of the CRS node (:class:`tlt_crs.node.CrsNode`, which builds the bridge
    in its process's ``main``): its context (whose ``node`` runs the bridge's timers and
    subscriptions), its command queue, and its tree as it ticks."""

    ctx: CrsContext
    commands: CommandQueue
    root: py_trees.behaviour.Behaviour
    shape: TreeShape
    tick_count: int
    tick_listeners: list[Callable[[], None]]

    def progress(self) -> Any: ...


class GroundBridge:
    """The CCSDS ground link of one CRS node (:class:`CrsTree`): opens the link from
    ``link_config`` (:func:`tlt_common.ccsds.link_config.load_link_config`) with the CRS's command
    path, and sends telemetry on the node's timers. :meth:`start` starts receiving commands.

    Raises what :meth:`GroundLink.from_config` raises (ConfigError, KeyFileError,
    ReplayStateError, OSError) before it touches the node.
    """

    def __init__(self, node: CrsTree, link_config: Mapping[str, Any]) -> None:
        self.node = node
        self.link = GroundLink.from_config(
            link_config, validator=self._check_on_arrival, on_command=self._queue_for_the_tree
        )
        # Every CRS event also goes to the ground, where operators read the event log.
        node.ctx.event_listeners.append(self._send_event)
        # The node announced itself (CRS_UP) before this bridge existed; the ground hears it here,
        # so a GSW following the build knows that a CRS (re)started and needs its Start again.
        mission, model = node.ctx.mission, node.ctx.model
        built = f"{model.bays_built()}/{mission.bay_count} bay(s) built"
        self._send_event(Severity.INFO, "CRS_UP", f"mission '{mission.name}': {built}; ground link up")
        self.tree_definitions = TreeDefinitionRelay(self._send)
        self._forward_ars_tree_statuses()
        # Telemetry has its own group: in the node's default one it waits behind the device
        # subscriptions' callbacks, and on a loaded machine the tree status may never go out.
        telemetry = MutuallyExclusiveCallbackGroup()
        for kind, send in (
            ("tree_status", self.send_tree_status),
            ("tree_definition", self.tree_definitions.resend),
            ("hk_mission", self.send_progress),
            ("hk_tower", self.send_tower),
            ("hk_lifter", self.send_lifter),
            ("hk_grippers", self.send_grippers),
            ("hk_ee", self.send_end_effectors),
            ("hk_arm_joints", self.send_arm_joints),
        ):
            rate = self.link.defs.packet(kind).rate_hz
            if rate:
                create_periodic_timer(node.ctx.node, 1.0 / rate, send, callback_group=telemetry)
        self._member_ids = {m.id for m in node.ctx.mission.members}
        self._last_step: tuple[Any, ...] | None = None
        self._last_progress: tuple[int, ...] | None = None
        self._steps: deque[tuple[dict[str, Any], bool]] = deque()
        node.tick_listeners.append(self.note_step)
        create_periodic_timer(
            node.ctx.node, 1.0 / node.ctx.config.tick_rate_hz, self.send_steps, callback_group=telemetry
        )

    def start(self) -> GroundBridge:
        """Start receiving ground commands."""
        self.link.start()
        return self

    def close(self) -> None:
        """Stop receiving and close the link."""
        self.link.close()

    def send_housekeeping(self) -> None:
        """Every housekeeping packet now (the last word of a stopping CRS)."""
        for send in (
            self.send_progress,
            self.send_lifter,
            self.send_grippers,
            self.send_end_effectors,
            self.send_arm_joints,
            self.send_tower,
        ):
            try:
                send()
            except Exception as exc:  # one packet that cannot be built must not cost the others
                _log.warning("housekeeping not sent: %s", exc)

    # ----- commands: validated on arrival, then queued for the tree -----
    def _check_on_arrival(self, command: GroundCommand) -> tuple[Reason, str] | None:
        """The CRS's rules for its state now, after the link's packet checks: a refusal becomes
        the command's one *rejected* acknowledgement, else the link acknowledges it *accepted*."""
        refusal = self.node.commands.check(command.name, command.params)
        return (Reason.REFUSED, refusal) if refusal else None

    def _queue_for_the_tree(self, command: GroundCommand) -> None:
        """Queue an accepted command; its outcome (the tree's execution check included) is its
        one *completed* or *failed* acknowledgement."""

        def on_outcome(stage: AckStage, reason: str) -> None:
            if stage is AckStage.COMPLETED:
                self.link.complete(command, True)
            else:
                self.link.complete(command, False, Reason.EXECUTION_FAILED, reason)

        self.node.commands.put_accepted(command.name, command.params, on_outcome)

    def _send_event(self, severity: int, code: str, text: str) -> None:
        try:
            self.link.send_event(Severity(min(int(severity), Severity.CRITICAL)), code, text)
        except Exception as exc:  # the ROS event went out; a ground link fault is not the tree's
            _log.warning("event %s not sent to the ground: %s", code, exc)

    def _forward_ars_tree_statuses(self) -> None:
        """Forward the ARSs' encoded tree statuses to the ground as they come, part by part, and
        their tree definitions (transient local: one published before this CRS started arrives
        too). The devices' states the housekeeping packets report come from the CRS's topic
        cache, which the tree and the Start check read too: one subscription per topic in the
        process (each message wakes the CRS's executor)."""
        from std_msgs.msg import String
        from tlt_interfaces.msg import TreeStatus

        for ars in ros_names.ARS_AGENTS:
            self.node.ctx.node.create_subscription(
                TreeStatus, ros_names.tree_status_topic(ars), self.forward_tree_status, 10
            )
            self.node.ctx.node.create_subscription(
                String,
                ros_names.tree_definition_topic(ars),
                functools.partial(self._on_tree_definition, ars),
                TreeStatusPublisher.DEFINITION_QOS,
            )

    def _on_tree_definition(self, ars: str, msg: Any) -> None:
        self.forward_tree_definition(ars, msg.data)

    def forward_tree_definition(self, ars: str, text: str) -> None:
        """An ARS's definition of the shape it moved to, on to the ground (a document that does
        not parse, or names another agent, is logged and dropped)."""
        try:
            agent, shape = parse_document_json(text)
        except StatusCodecError as exc:
            _log.warning("tree definition from %s dropped: %s", ars, exc)
            return
        if agent != ars:
            _log.warning("tree definition on %s's topic names agent %r: dropped", ars, agent)
            return
        self.tree_definitions.shape(ars, shape)

    def _latest(self, topic: str) -> Any:
        """The newest message on a device topic, or None before the first."""
        entry = self.node.ctx.cache.latest(topic)
        return None if entry is None else entry[0]

    def _send(self, kind: str, values: dict[str, Any]) -> None:
        try:
            self.link.send_telemetry(kind, values)
        except (KeyError, ValueError) as exc:  # a value outside its definition: say so, keep going
            _log.warning("%s not sent: %s", kind, exc)

    def send_lifter(self) -> None:
        msg = self._latest(ros_names.state_topic(ros_names.LIFTER))
        if msg is None:
            return
        switches = sum(1 << i for i, pressed in enumerate(msg.limit_switches) if pressed)
        self._send(
            "hk_lifter",
            {
                "state": int(msg.state),
                **{f"position_{i}": float(p) for i, p in enumerate(msg.encoder_positions)},
                # One figure for a glance at the lifter: the fastest motor.
                "velocity": int(max(msg.motor_velocities, key=abs)),
                "limit_switches": switches,
                "watchdog_tripped": bool(msg.watchdog_tripped),
                "link_ok": bool(msg.link_ok),
            },
        )

    def send_grippers(self) -> None:
        top = self._latest(ros_names.state_topic(ros_names.TOP_GRIPPERS))
        active = self._latest(ros_names.state_topic(ros_names.ACTIVE_GRIPPERS))
        lifter = self._latest(ros_names.state_topic(ros_names.LIFTER))
        if top is None and active is None:
            return

        def bits(flags) -> int:
            return sum(1 << i for i, on in enumerate(flags) if on)

        self._send(
            "hk_grippers",
            {
                "top_engaged": bits(top.engaged) if top else 0,
                "top_position_mean": sum(top.position) / len(top.position) if top and top.position else 0.0,
                "top_fault": bool(top.fault) if top else True,
                "active_engaged": bits(active.engaged) if active else 0,
                # The Active Grippers ride the lead screws: their height is the lifter's position.
                "active_height": (sum(lifter.encoder_positions) / 4.0) if lifter else 0.0,
                "active_fault": bool(active.fault) if active else True,
            },
        )

    def send_end_effectors(self) -> None:
        for ars in ros_names.ARS_AGENTS:
            msg = self._latest(ros_names.state_topic(ros_names.ee(ars)))
            if msg is None or len(msg.position) < 3:
                continue
            self._send(
                "hk_ee",
                {
                    "ars": ars,
                    "grasp_left": float(msg.position[0]),
                    "grasp_right": float(msg.position[1]),
                    "width": float(msg.position[2]),
                    "max_load": float(max(msg.effort, key=abs)) if len(msg.effort) else 0.0,
                    "calibrated": bool(msg.calibrated),
                    "part_grasped": bool(msg.part_grasped),
                    "rivet_guns": sum(1 << i for i, on in enumerate(msg.rivet_gun_output) if on),
                    "fault": bool(msg.fault),
                },
            )

    def send_arm_joints(self) -> None:
        for ars in ros_names.ARS_AGENTS:
            joints = self._latest(ros_names.joint_states_topic(ros_names.ur(ars)))
            if joints is None or len(joints.position) != 6:
                continue
            status = self._latest(ros_names.hardware_status_topic(ros_names.ur(ars)))
            self._send(
                "hk_arm_joints",
                {
                    "ars": ars,
                    **{f"q{i}": float(q) for i, q in enumerate(joints.position)},
                    "protective_stop": bool(status and "protective stop" in status.fault.lower()),
                },
            )

    def send_tower(self) -> None:
        with self.node.ctx.model.lock:
            states = [m.state for m in self.node.ctx.model.member_states()]
        self._send("hk_tower", {"member_count": len(states), "member_states": pack_member_states(states)})

    def forward_tree_status(self, msg: Any) -> None:
        if msg.agent not in ros_names.ARS_AGENTS:
            return
        self._send(
            "tree_status",
            {
                "agent": msg.agent,
                "shape_hash": msg.shape_hash,
                "tick": msg.tick_count,
                "node_count": msg.node_count,
                "part_index": msg.part_index,
                "part_count": msg.part_count,
                "first_node": msg.first_node,
                "status": bytes(msg.status),
            },
        )

    def send_tree_status(self) -> None:
        node = self.node
        with node.ctx.lock:
            shape = node.shape
            parts = encode(
                shape, agent="crs", tick_count=node.tick_count, max_status_bytes=STATUS_BYTES_PER_PACKET
            )
        self.tree_definitions.shape("crs", shape)  # before the first status of a new shape
        for part in parts:
            self.link.send_telemetry(
                "tree_status",
                {
                    "agent": "crs",
                    "shape_hash": part.shape_hash,
                    "tick": part.tick_count,
                    "node_count": part.node_count,
                    "part_index": part.part_index,
                    "part_count": part.part_count,
                    "first_node": part.first_node,
                    "status": part.status,
                },
            )

    def _step_of(self, tip: Any) -> tuple[int | None, str, str]:
        """(bay, member or phase, step) of the running leaf ``tip``; bay None outside a bay's
        subtree (foundation rivets, Wait For Help)."""
        if tip is None:
            return None, "", ""
        bay: int | None = None
        member = ""
        node = tip
        while node is not None:
            parent = node.parent
            last = node.name.rsplit(" ", 1)[-1]
            if not member and last in self._member_ids:
                member = last
            if parent is not None and parent.name.startswith("Construct Bay "):
                # A step outside any member's subtree belongs to its bay's phase (Index Payload n, ...).
                member = member or node.name
                bay = int(parent.name.rsplit(" ", 1)[-1])
                break
            node = parent
        return bay, member, tip.name

    def note_step(self) -> None:
        """Queue a ``mission_step`` if the step or progress changed (the node calls this at the end
        of each tick, holding the context's lock)."""
        ctx = self.node.ctx
        root = self.node.root
        tip = root.tip() if root.status == Status.RUNNING else None
        bay, member, step = self._step_of(tip)
        if bay is None:
            bay = int(ctx.board.get("current_bay", 0) or 0)
        run_state = ctx.run_state
        with ctx.model.lock:
            bays_built = ctx.model.bays_built()
            placed = sum(state >= PLACED for state in ctx.model.states.values())
            riveted = sum(state >= RIVETED for state in ctx.model.states.values())
            discarded = sum(ctx.model.discarded.values())
        key = (int(run_state), bay, member, step, bays_built, placed, discarded)
        if key == self._last_step:
            return
        progress = (int(run_state), bays_built, placed, discarded, riveted)
        progressed = self._last_step is None or progress != self._last_progress
        self._last_step, self._last_progress = key, progress
        fields = {
            "sim_time": ctx.ros_seconds(),
            "run_state": int(run_state),
            "bay": bay,
            "member": member[:64],
            "step": step[:80],
            "bays_built": bays_built,
            "members_placed": placed,
            "parts_discarded": discarded,
        }
        self._steps.append((fields, progressed))

    def send_steps(self) -> None:
        """Send the queued ``mission_step`` packets, in order."""
        if self._flush_steps():
            # The ground's view of the tower follows each change, not only the next periodic packet.
            self.send_progress()
            self.send_tower()

    def _flush_steps(self) -> bool:
        """Send what is queued; True if any of it changed the progress."""
        progressed = False
        while self._steps:
            fields, changed = self._steps.popleft()
            self._send("mission_step", fields)
            progressed = progressed or changed
        return progressed

    def send_progress(self) -> None:
        """``hk_mission``, never ahead of ``mission_step``: the state it reports is noted as a step
        and sent first. The model changes in an ARS result's callback, between ticks; a "done" in
        ``hk_mission`` before the step saying so ended the ground's job with the foundation's
        phase unfinished."""
        with self.node.ctx.lock:
            self.note_step()
            msg: Any = self.node.progress()
        progressed = self._flush_steps()
        members = list(msg.members)
        self.link.send_telemetry(
            "hk_mission",
            {
                "run_state": int(msg.run_state),
                "started": bool(msg.started),
                "bays_total": msg.bays_total,
                "bays_built": msg.bays_built,
                "current_bay": msg.current_bay,
                "members_total": len(members),
                "members_placed": sum(m.state >= m.STATE_PLACED for m in members),
                "members_riveted": sum(m.state >= m.STATE_RIVETED for m in members),
                "current_step": msg.current_step[:80],
                "fault": msg.fault[:120],
            },
        )
        if progressed:
            self.send_tower()
