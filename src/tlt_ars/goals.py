"""What a CRS goal is to the ARS: the action type of each request, the :class:`Request` a goal
carries, and :class:`ActiveGoal`, a goal in work and how it ends (:class:`tlt_ars.node.ArsNode`
serves them).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

from tlt_interfaces.action import AddCrossFrame, AddMember, AffixMember, FoundationRivet

from tlt_ars.mission_state import Request

ACTION_TYPES = {
    "add_cross_frame": AddCrossFrame,
    "add_member": AddMember,
    "affix_member": AffixMember,
    "foundation_rivet": FoundationRivet,
}


def request_of(kind: str, goal: Any) -> Request:
    """The CRS goal of request ``kind`` as a :class:`Request`."""
    if kind == "foundation_rivet":
        return Request(kind, goal.joint_id, goal.ars)
    return Request(
        kind,
        goal.member_id,
        goal.ars,
        bay=int(goal.bay),
        kind=int(getattr(goal, "kind", 0)),
        position=getattr(goal, "position", ""),
        joint=getattr(goal, "joint", ""),
    )


@dataclass
class ActiveGoal:
    """The goal the ARS is working on, and how it ends."""

    kind: str
    handle: Any
    request: Request
    done: threading.Event
    outcome: tuple[str, str] | None = None  # ("succeeded" | "aborted" | "canceled", reason)
    cancel_requested: bool = False
    stopping_since: float | None = None
    discarded_from: list[str] = field(default_factory=list)  # the dispenser of each part discarded
    joints: list[Any] = field(default_factory=list)  # JointCheck of the request's joint, if looked at
    successor: ActiveGoal | None = None  # the newer goal for the same request that took the job over
    feedback: tuple[str, float] | None = None  # the step and progress last sent to the CRS


__all__ = ["ACTION_TYPES", "ActiveGoal", "request_of"]
