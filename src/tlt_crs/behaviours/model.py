"""Conditions on the tower model, and the model updates that follow ARS results (paper §V.C.1).

Conditions read the model (``tower_built``, "bay N built?", "member placed?") as §V.C.2 says for
conditions driven by the mission rather than by a sensor. The ``record_*`` functions turn an ARS
result into model changes: placement, rivets, parts taken from and discarded at each dispenser.
The model refuses impossible changes (``TransitionRefused``); such a refusal here means the model
and the robot disagree, which is reported as a warning event rather than stopping the CRS, since
the ARS result describes what physically happened.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from py_trees.common import Status

from tlt_common.bt.nodes import Action, Condition
from tlt_common.mission.schema import Member
from tlt_common.mission.tower_model import INSPECTED, PLACED, RIVETED, STATE_NAMES, TransitionRefused
from tlt_crs.behaviours.joints import record_joints
from tlt_crs.context import CrsContext


class MemberAtLeast(Condition):
    """True when ``member`` is at least ``state`` (PLACED, RIVETED or INSPECTED) in the tower model.

    Reads: the tower model. Writes: nothing. SUCCESS when it is; FAILURE otherwise.
    """

    def __init__(self, ctx: CrsContext, member: Member, state: int) -> None:
        super().__init__(f"{member.id} {STATE_NAMES[state].lower()}?")
        self.ctx = ctx
        self.member_id = member.id
        self.state = state

    def evaluate(self) -> bool:
        return self.ctx.model.states[self.member_id] >= self.state


class BayBuilt(Condition):
    """True when every member of bay ``bay`` is INSPECTED (built and passed Test Bay).

    Reads: the tower model. SUCCESS when built, so the bay's subtree is skipped; FAILURE otherwise.
    """

    def __init__(self, ctx: CrsContext, bay: int) -> None:
        super().__init__(f"Bay {bay} Built?")
        self.ctx = ctx
        self.ids = [m.id for m in ctx.mission.bay_members(bay)]
        self._answer = (-1, False)  # (model revision, answer): re-evaluated only when the model changed

    def evaluate(self) -> bool:
        revision = self.ctx.model.revision
        if self._answer[0] != revision:
            states = self.ctx.model.states
            self._answer = (revision, all(states[i] == INSPECTED for i in self.ids))
        return self._answer[1]


class BayIndexed(Condition):
    """True when the payload was indexed for bay ``bay``: recorded, a member of the bay is placed,
    or it is bay 1 on a machine that starts indexed (``lifter.indexed_at_start``).

    Reads: the index record, the tower model and the configuration. SUCCESS/FAILURE accordingly.
    """

    def __init__(self, ctx: CrsContext, bay: int) -> None:
        super().__init__(f"Bay {bay} Indexed?")
        self.ctx = ctx
        self.bay = bay
        self.ids = [m.id for m in ctx.mission.bay_members(bay)]

    def evaluate(self) -> bool:
        states = self.ctx.model.states
        if self.bay == 1 and self.ctx.config.lifter.indexed_at_start:
            return True
        return self.ctx.index.indexed(self.bay) or any(states[i] >= PLACED for i in self.ids)


class TowerBuilt(Condition):
    """``tower_built``: every member and foundation rivet done, from the tower model.

    Reads: the tower model. Writes: blackboard ``tower_built``. SUCCESS when built.
    """

    def __init__(self, ctx: CrsContext) -> None:
        super().__init__("Tower Built?")
        self.ctx = ctx
        self._answer = (-1, False)  # (model revision, answer): re-evaluated only when the model changed

    def evaluate(self) -> bool:
        revision = self.ctx.model.revision
        if self._answer[0] != revision:
            built = self.ctx.model.tower_built
            self.ctx.board.set("tower_built", built)
            self._answer = (revision, built)
        return self._answer[1]


class BoardFlag(Condition):
    """True when blackboard ``key`` is true (``started``, ``skip_bay_inspection``).

    Reads: ``key``. SUCCESS when true; FAILURE when false or unset.
    """

    def __init__(self, ctx: CrsContext, name: str, key: str) -> None:
        super().__init__(name)
        self.ctx = ctx
        self.key = key

    def evaluate(self) -> bool:
        return bool(self.ctx.board.get(self.key, False))


class RecordBayIndexed(Action):
    """Persist that the payload was indexed for ``bay``. Writes: the index record. SUCCESS at once."""

    def __init__(self, ctx: CrsContext, bay: int) -> None:
        super().__init__(f"Record Bay {bay} Indexed")
        self.ctx = ctx
        self.bay = bay

    def update(self) -> Status:
        self.ctx.index.record(self.bay)
        return Status.SUCCESS


class SetCurrentBay(Action):
    """Writes blackboard ``current_bay``. SUCCESS at once."""

    def __init__(self, ctx: CrsContext, bay: int) -> None:
        super().__init__(f"Current Bay {bay}")
        self.ctx = ctx
        self.bay = bay

    def update(self) -> Status:
        self.ctx.board.set("current_bay", self.bay)
        return Status.SUCCESS


class RecordBayInspected(Action):
    """Mark every member of ``bay`` INSPECTED after Test Bay. Writes: the tower model. SUCCESS."""

    def __init__(self, ctx: CrsContext, bay: int) -> None:
        super().__init__(f"Record Bay {bay} Inspected")
        self.ctx = ctx
        self.bay = bay

    def update(self) -> Status:
        for member in self.ctx.mission.bay_members(self.bay):
            if self.ctx.model.states[member.id] != INSPECTED:
                _apply(self.ctx, self.ctx.model.inspect, member.id)
        return Status.SUCCESS


def _apply(ctx: CrsContext, change: Any, *args: Any) -> None:
    try:
        change(*args)
    except TransitionRefused as exc:
        ctx.event(2, "MODEL_DISAGREES", f"tower model refused an update after an ARS result: {exc.reason}")


def discarded_dispensers(member: Member, result: Any) -> Counter[str]:
    """How many parts the ARS discarded from each dispenser while it worked on ``member``. The
    result names each part's dispenser: a part a failed request left in the gripper, discarded
    first by the next request, need not be of that request's member. A part counted and not named
    (an empty name, or an ARS whose result has no names) is taken to be from the member's."""
    named = [d for d in getattr(result, "discarded_from", ()) or () if d]
    unnamed = int(getattr(result, "parts_discarded", 0) or 0) - len(named)
    return Counter(named + [member.dispenser] * max(0, unnamed))


def record_parts(ctx: CrsContext, member: Member, result: Any, ok: bool) -> None:
    """Parts the ARS took for ``member``: the placed one if ``ok``, from the member's dispenser,
    and each discarded one, taken and discarded from its own dispenser."""
    discarded = discarded_dispensers(member, result)
    taken = discarded + Counter({member.dispenser: 1} if ok else {})
    for dispenser, count in taken.items():
        _apply(ctx, ctx.model.take_part, dispenser, count)
    for dispenser, count in discarded.items():
        _apply(ctx, ctx.model.discard_part, dispenser, count)


def record_rivets(ctx: CrsContext, member: Member, step: str) -> None:
    for rivet in member.rivets:
        if rivet.step == step:
            _apply(ctx, ctx.model.take_part, rivet.dispenser, 1)


def record_added(ctx: CrsContext, member: Member, result: Any, ok: bool) -> None:
    """After AddCrossFrame/AddMember: parts, the add-step rivets, PLACED (and RIVETED when the
    member has no affix step, e.g. a diagonal), the joint the ARS verified
    (:func:`tlt_crs.behaviours.joints.record_joints`)."""
    with ctx.model.lock:
        record_parts(ctx, member, result, ok)
        if not ok:
            return
        record_rivets(ctx, member, "add")
        record_joints(ctx, member, result)
        if ctx.model.states[member.id] < PLACED:
            _apply(ctx, ctx.model.place, member.id)
        needs_affix = any(r.step == "affix" for r in member.rivets)
        if member.kind != "cross_frame" and not needs_affix and ctx.model.states[member.id] < RIVETED:
            _apply(ctx, ctx.model.rivet, member.id)


def record_affixed(ctx: CrsContext, member: Member, result: Any, ok: bool) -> None:
    """After AffixMember: the affix-step rivets, RIVETED, the joint the ARS verified."""
    if not ok:
        return
    with ctx.model.lock:
        record_rivets(ctx, member, "affix")
        record_joints(ctx, member, result)
        if ctx.model.states[member.id] < RIVETED:
            _apply(ctx, ctx.model.rivet, member.id)


def record_foundation_rivet(ctx: CrsContext, member: Member, result: Any, ok: bool) -> None:
    """After FoundationRivet: one rivet from its dispenser and RIVETED."""
    if not ok:
        return
    with ctx.model.lock:
        _apply(ctx, ctx.model.take_part, member.dispenser, 1)
        if ctx.model.states[member.id] < RIVETED:
            _apply(ctx, ctx.model.rivet, member.id)


__all__ = [
    "BayBuilt",
    "BayIndexed",
    "BoardFlag",
    "MemberAtLeast",
    "RecordBayIndexed",
    "RecordBayInspected",
    "SetCurrentBay",
    "TowerBuilt",
    "record_added",
    "record_affixed",
    "record_foundation_rivet",
]
