"""The CCSDS ground link inside the CRS process: ground commands into the tree, telemetry out.

Commands arrive authenticated on the link's receive thread. Each is checked against the CRS's
state before the link acknowledges it (a Pause while not started, a blackboard write outside the
writable registry or an actuator command while building is refused with the reason, and never
acts), then queued for the tree, which processes it on its next tick (Fig. 13); the outcome goes
back to the ground as the completed or failed acknowledgement.

Telemetry: the CRS tree's encoded status (``tree_status``, one packet per part) and mission
progress (``hk_mission``), each at its rate in the definitions file, and every CRS event.
"""

from __future__ import annotations

import logging
from typing import Any

from tlt_common.bt.status_codec import encode
from tlt_common.ccsds.reasons import AckStage, Reason, Severity
from tlt_crs.ground_link.link import GroundCommand, GroundLink
from tlt_crs.node import CrsNode

_log = logging.getLogger("tlt_crs.ground_bridge")
# Status bytes per tree_status packet: the definition allows 1024; 256 keeps packets small.
STATUS_BYTES_PER_PACKET = 256


class GroundBridge:
    """Connects a :class:`GroundLink` to a :class:`CrsNode`; the node's timers send telemetry."""

    def __init__(self, node: CrsNode, link: GroundLink) -> None:
        self.node = node
        self.link = link
        link.validator = self._validate
        link.on_command = self._on_command
        # Every CRS event also goes to the ground, where operators read the event log.
        publish_event = node.ctx.event

        def event(severity: int, code: str, text: str) -> None:
            publish_event(severity, code, text)
            try:
                link.send_event(Severity(min(int(severity), Severity.CRITICAL)), code, text)
            except Exception as exc:  # the ROS event went out; a ground link fault is not the tree's
                _log.warning("event %s not sent to the ground: %s", code, exc)

        node.ctx.event = event
        for kind, send in (("tree_status", self.send_tree_status), ("hk_mission", self.send_progress)):
            rate = link.defs.packet(kind).rate_hz
            if rate:
                node.create_timer(1.0 / rate, send)

    def _validate(self, command: GroundCommand) -> tuple[Reason, str] | None:
        refusal = self.node.commands.check(command.name, command.params)
        return (Reason.REFUSED, refusal) if refusal else None

    def _on_command(self, command: GroundCommand) -> None:
        def on_ack(stage: AckStage, reason: str) -> None:
            # The link acknowledged acceptance itself; a refusal that raced the check above is a
            # failure to execute, with the CRS's reason.
            if stage is AckStage.COMPLETED:
                self.link.complete(command, True)
            elif stage in (AckStage.FAILED, AckStage.REJECTED):
                self.link.complete(command, False, Reason.EXECUTION_FAILED, reason)

        self.node.commands.submit(command.name, command.params, on_ack)

    def send_tree_status(self) -> None:
        node = self.node
        with node.ctx.lock:
            parts = encode(
                node.shape, agent="crs", tick_count=node.tick_count, max_status_bytes=STATUS_BYTES_PER_PACKET
            )
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

    def send_progress(self) -> None:
        msg: Any = self.node.progress()
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
