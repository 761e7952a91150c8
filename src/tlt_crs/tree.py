"""The CRS behaviour tree (paper Fig. 13 and Figs. 18-27), built from mission data.

Every subtree has its own builder and can be built and ticked alone (the tests do, bottom-up, as
§VII recommends). The shape::

    CRS                                   Sequence (no memory: the guards are checked every tick)
      Initialise Blackboard               mission defaults, writable registry defaults
      Process Ground Command              one queued command per tick
      Fault Check                         Fallback[No Fault?, Wait For Help]
      Started?                            false at start-up
      Lifter Link Watch                   holds the build while the lifter link is down (always SUCCESS)
      Tower                               Fallback[Tower Built?, Hold While Paused[Build Tower], Raise Fault]
        Build Tower                       Sequence: Bay 1 .. Bay N, Add Foundation Rivets
          Bay n                           Fallback(memory)[Bay n Built?, Sequence(memory)[...]]
            Index Payload n               Fallback(memory)[Bay n Indexed?, [Raise, Lower, record]]
            Current Bay n
            Build Bay n                   Add Cross Frame, Far Verticals, Near Verticals, Diagonals
                                          (each strut followed by Joints <member>: its verified
                                          rivets, or the operator's decision)
            Test Bay n                    Fig. 26
          Add Foundation Rivets           Fig. 27

Guards are conditions on the tower model (member placed/riveted, bay built, tower built) or on
sensors (grippers engaged, lifter position and state). Work sequences have memory, and each
guard-plus-work pair is a Fallback with memory, so a guard is checked when a step starts, not
while it runs. After a fault, a restart or a resume, the tree walks past everything the model and
the sensors say is done: a finished bay costs one condition per tick, and a member the model says
is placed is never requested again.
"""

from __future__ import annotations

from typing import Any

import py_trees
from py_trees.common import Status

from tlt_common import ros_names
from tlt_common.bt.nodes import Action
from tlt_common.bt.ros import ServiceCall
from tlt_common.mission.schema import Member
from tlt_common.mission.tower_model import PLACED, RIVETED
from tlt_crs.behaviours.actuators import Actuators
from tlt_crs.behaviours.ars_requests import ArsRequest, AwaitArsResult, RequestScope, SendArsRequest
from tlt_crs.behaviours.faults import NoFault, RaiseFault, WaitForHelp
from tlt_crs.behaviours.inspection import inspection_check
from tlt_crs.behaviours.joints import ApplyJointDecision, JointsAccepted, reshot_request
from tlt_crs.behaviours.link_watch import LifterLinkWatch
from tlt_crs.behaviours.model import (
    BayBuilt,
    BayIndexed,
    BoardFlag,
    MemberAtLeast,
    RecordBayIndexed,
    RecordBayInspected,
    SetCurrentBay,
    TowerBuilt,
    record_added,
    record_affixed,
    record_foundation_rivet,
)
from tlt_crs.commands import CommandProcessor, ProcessGroundCommand
from tlt_crs.context import CrsContext

Sequence = py_trees.composites.Sequence
Fallback = py_trees.composites.Selector
KIND_CODES = {"vertical": 1, "diagonal": 2}  # AddMember/AffixMember KIND_*


def _guarded(name: str, guard: py_trees.behaviour.Behaviour, work: py_trees.behaviour.Behaviour) -> Fallback:
    return Fallback(name, memory=True, children=[guard, work])


class InitialiseBlackboard(Action):
    """Initialise the blackboard from the mission and the writable registry (Fig. 13, first step).

    Writes: every registry key with a default, ``cross_frame_ars`` (the mission's ARS for the
    cross frame), ``started`` = false, ``fault`` = "", ``current_bay``, ``tower_built``.
    SUCCESS (at once; later ticks find it done).
    """

    def __init__(self, ctx: CrsContext) -> None:
        super().__init__("Initialise Blackboard")
        self.ctx = ctx
        self.done = False

    def update(self) -> Status:
        if not self.done:
            ctx, board = self.ctx, self.ctx.board
            first = ctx.model.next_member() or ctx.mission.members[0]
            cross_frames = [m for m in ctx.mission.members if m.kind == "cross_frame"]
            if board.get("cross_frame_ars") is None and cross_frames:
                board.set("cross_frame_ars", cross_frames[0].add_ars)
            ctx.registry.initialise_defaults()
            for key, value in (("started", False), ("fault", ""), ("clear_fault", False)):
                if board.get(key) is None:
                    board.set(key, value)
            board.set("current_bay", ctx.model.bays_built() + (0 if ctx.model.tower_built else 1))
            board.set("tower_built", ctx.model.tower_built)
            self.done = True
            self.feedback_message = f"mission '{ctx.mission.name}', next member {first.id}"
        return Status.SUCCESS


class HoldWhilePaused(py_trees.decorators.Decorator):
    """While the CRS is paused or held (a device link down), answer RUNNING without ticking the
    child, so its running behaviours (an ARS goal in flight, a sequence's place) stay as they are
    and Resume, or the link's return, continues them.

    Reads: the mission clock's holds, ``ctx.link_fault``. RUNNING while held; else the child's status.
    """

    def __init__(self, ctx: CrsContext, child: py_trees.behaviour.Behaviour) -> None:
        super().__init__(name="Hold While Paused", child=child)
        self.ctx = ctx

    def tick(self) -> Any:
        if self.ctx.clock.held:
            self.status = Status.RUNNING
            self.feedback_message = f"held: {self.ctx.link_fault}" if self.ctx.link_fault else "paused"
            yield self
            return
        self.feedback_message = ""
        # py_trees' Decorator.tick (2.6) written out rather than ``yield from super().tick()``:
        # this decorator sits above Build Tower, and a second generator frame here would be passed
        # through by every node ticked below it.
        self.logger.debug(f"{self.__class__.__name__}.tick()")
        if self.status != Status.RUNNING:
            self.initialise()
        yield from self.decorated.tick()
        new_status = self.update()
        if new_status != Status.RUNNING:
            self.stop(new_status)
        self.status = new_status
        yield self

    def update(self) -> Status:
        return self.decorated.status


# ----- ARS requests (Figs. 21, 23, 24, 25, 27) ----------------------------------------------------
def _request(ctx: CrsContext, request: ArsRequest, inspected: bool, name: str = "") -> RequestScope:
    children: list[py_trees.behaviour.Behaviour] = [SendArsRequest(request)]
    if inspected:
        children.append(inspection_check(ctx, request))
    children.append(AwaitArsResult(request))
    verb = {
        "add_cross_frame": "Add",
        "add_member": "Add",
        "affix_member": "Affix",
        "foundation_rivet": "Rivet",
    }
    return RequestScope(name or f"{verb[request.request]} {request.member.id}", request, children)


def add_member_request(ctx: CrsContext, member: Member) -> ArsRequest:
    from tlt_interfaces.action import AddMember

    def goal(ars: str) -> Any:
        return AddMember.Goal(
            kind=KIND_CODES[member.kind],
            bay=member.bay,
            member_id=member.id,
            position=member.position,
            ars=ars,
        )

    return ArsRequest(
        ctx, AddMember, "add_member", member, member.add_ars, goal, record_added, inspected=True
    )


def affix_member_request(ctx: CrsContext, member: Member) -> ArsRequest:
    from tlt_interfaces.action import AffixMember

    assert member.affix_ars is not None

    def goal(ars: str) -> Any:
        return AffixMember.Goal(
            kind=KIND_CODES[member.kind],
            bay=member.bay,
            member_id=member.id,
            position=member.position,
            ars=ars,
        )

    return ArsRequest(ctx, AffixMember, "affix_member", member, member.affix_ars, goal, record_affixed)


def add_cross_frame(ctx: CrsContext, member: Member, actuators: Actuators) -> py_trees.behaviour.Behaviour:
    """Fig. 21: request, Inspection Check (Fig. 22), wait for the ARS, engage the Active Grippers."""
    from tlt_interfaces.action import AddCrossFrame

    def goal(ars: str) -> Any:
        return AddCrossFrame.Goal(bay=member.bay, member_id=member.id, ars=ars)

    def ars() -> str:
        return str(ctx.board.get("cross_frame_ars") or member.add_ars)

    request = ArsRequest(
        ctx, AddCrossFrame, "add_cross_frame", member, ars, goal, record_added, inspected=True
    )
    return Sequence(
        f"Add Cross Frame {member.bay}",
        memory=True,
        children=[
            _guarded(f"Place {member.id}", MemberAtLeast(ctx, member, PLACED), _request(ctx, request, True)),
            actuators.active_grippers(True),
        ],
    )


def member_joints(ctx: CrsContext, member: Member) -> py_trees.behaviour.Behaviour:
    """The member's riveted joints as the ARSs verified them (:mod:`tlt_crs.behaviours.joints`):
    accepted (each verified or confirmed, or never looked at), or the operator's decision (the
    fault with the evidence until there is one), a retry when ordered, and the check again."""
    retry = _request(ctx, reshot_request(ctx, member), False, name=f"Retry {member.id}")
    return Fallback(
        f"Joints {member.id}",
        memory=True,
        children=[
            JointsAccepted(ctx, member),
            Sequence(
                f"Resolve Joints {member.id}",
                memory=True,
                children=[
                    ApplyJointDecision(ctx, member),
                    Fallback(
                        f"Retry Joints {member.id}",
                        memory=True,
                        children=[JointsAccepted(ctx, member), retry],
                    ),
                    JointsAccepted(ctx, member),
                ],
            ),
        ],
    )


def add_vertical(ctx: CrsContext, member: Member) -> py_trees.behaviour.Behaviour:
    """Fig. 23 (far: one ARS adds, the other affixes) and Fig. 24 (near: the same ARS does both)."""
    kind = "Far" if member.group == "far_vertical" else "Near"
    add = _request(ctx, add_member_request(ctx, member), True)
    affix = _request(ctx, affix_member_request(ctx, member), False)
    return Sequence(
        f"Add {kind} Vertical {member.position}",
        memory=True,
        children=[
            _guarded(f"Added {member.id}", MemberAtLeast(ctx, member, PLACED), add),
            _guarded(f"Affixed {member.id}", MemberAtLeast(ctx, member, RIVETED), affix),
        ],
    )


def add_diagonal(ctx: CrsContext, member: Member) -> py_trees.behaviour.Behaviour:
    """Fig. 25: Add Member with the diagonal's parameters, Inspection Check, wait for the ARS."""
    return _guarded(
        f"Add Diagonal {member.position}",
        MemberAtLeast(ctx, member, RIVETED),
        _request(ctx, add_member_request(ctx, member), True),
    )


def _group(ctx: CrsContext, bay: int, group: str) -> list[Member]:
    return [m for m in ctx.mission.bay_members(bay) if m.group == group]


def _struts(ctx: CrsContext, bay: int, group: str, add: Any) -> list[py_trees.behaviour.Behaviour]:
    """Each strut of ``group``'s subtree (``add``, its figure), then its joints (:func:`member_joints`)."""
    return [node for m in _group(ctx, bay, group) for node in (add(ctx, m), member_joints(ctx, m))]


def build_bay(ctx: CrsContext, bay: int, actuators: Actuators) -> py_trees.behaviour.Behaviour:
    """Fig. 20: cross frame, far verticals, near verticals, diagonals; each strut's joints after
    its figure's subtree."""
    cross_frame = _group(ctx, bay, "cross_frame")[0]
    return Sequence(
        f"Build Bay {bay}",
        memory=True,
        children=[
            add_cross_frame(ctx, cross_frame, actuators),
            Sequence(
                f"Far Verticals {bay}",
                memory=True,
                children=_struts(ctx, bay, "far_vertical", add_vertical),
            ),
            Sequence(
                f"Near Verticals {bay}",
                memory=True,
                children=_struts(ctx, bay, "near_vertical", add_vertical),
            ),
            Sequence(
                f"Diagonals {bay}",
                memory=True,
                children=_struts(ctx, bay, "diagonal", add_diagonal),
            ),
        ],
    )


def bay_test(ctx: CrsContext, bay: int, actuators: Actuators) -> py_trees.behaviour.Behaviour:
    """Fig. 26: engage Top and Active, CRS Control, compression, cameras in, bay inspection, cameras out."""
    from tlt_interfaces.srv import InspectBay

    def inspection_ok(response: Any) -> tuple[bool, str]:
        # Each verdict is an event: Test Bay only fails on a bad bay, and a pass would leave no trace.
        report = response.report
        reasons = "; ".join(report.reasons)
        if report.passed:
            ctx.event(1, "BAY_INSPECTION_PASSED", f"bay {bay} passed inspection")
        else:
            ctx.event(2, "BAY_INSPECTION_FAILED", f"bay {bay} failed inspection: {reasons}")
        return bool(report.passed), reasons

    inspect = ServiceCall(
        f"Inspect Bay {bay}",
        ctx.node,
        InspectBay,
        ros_names.VISION_INSPECT_BAY,
        lambda: InspectBay.Request(bay=bay),
        response_ok=inspection_ok,
        **ctx.vision_call_options(),
    )
    return Sequence(
        f"Test Bay {bay}",
        memory=True,
        children=[
            actuators.top_grippers(True),
            actuators.active_grippers(True),
            actuators.lifter_crs_control(),
            actuators.compression(),
            actuators.cameras(inward=True),
            Fallback(
                f"Bay Inspection {bay}",
                memory=True,
                children=[BoardFlag(ctx, "Skip Bay Inspection?", "skip_bay_inspection"), inspect],
            ),
            actuators.cameras(inward=False),
            RecordBayInspected(ctx, bay),
        ],
    )


def index_payload(ctx: CrsContext, bay: int, actuators: Actuators) -> py_trees.behaviour.Behaviour:
    """Raise Payload (Fig. 18) and Lower Lifter (Fig. 19), once per bay (persisted)."""
    return _guarded(
        f"Index Payload {bay}",
        BayIndexed(ctx, bay),
        Sequence(
            f"Index {bay}",
            memory=True,
            children=[actuators.raise_payload(), actuators.lower_lifter(), RecordBayIndexed(ctx, bay)],
        ),
    )


def bay_subtree(ctx: CrsContext, bay: int, actuators: Actuators) -> py_trees.behaviour.Behaviour:
    """One bay, skipped at the cost of one condition once the model says it is built."""
    return _guarded(
        f"Bay {bay}",
        BayBuilt(ctx, bay),
        Sequence(
            f"Construct Bay {bay}",
            memory=True,
            children=[
                index_payload(ctx, bay, actuators),
                SetCurrentBay(ctx, bay),
                build_bay(ctx, bay, actuators),
                bay_test(ctx, bay, actuators),
            ],
        ),
    )


def add_foundation_rivets(ctx: CrsContext) -> py_trees.behaviour.Behaviour:
    """Fig. 27: a Foundation Rivet request per foundation joint, each waiting for the ARS."""
    from tlt_interfaces.action import FoundationRivet

    children = []
    for member in (m for m in ctx.mission.members if m.kind == "foundation_rivet"):

        def goal(ars: str, member: Member = member) -> Any:
            return FoundationRivet.Goal(joint_id=member.id, ars=ars)

        request = ArsRequest(
            ctx, FoundationRivet, "foundation_rivet", member, member.add_ars, goal, record_foundation_rivet
        )
        children.append(
            _guarded(
                f"Rivet {member.position}", MemberAtLeast(ctx, member, RIVETED), _request(ctx, request, False)
            )
        )
    return Sequence("Add Foundation Rivets", memory=True, children=children)


def build_tower(ctx: CrsContext, actuators: Actuators | None = None) -> py_trees.behaviour.Behaviour:
    actuators = actuators or Actuators(ctx)
    bays = [bay_subtree(ctx, n, actuators) for n in range(1, ctx.mission.bay_count + 1)]
    return Sequence("Build Tower", memory=False, children=[*bays, add_foundation_rivets(ctx)])


def fault_check(ctx: CrsContext) -> py_trees.behaviour.Behaviour:
    return Fallback("Fault Check", memory=False, children=[NoFault(ctx), WaitForHelp(ctx)])


def build_crs_tree(ctx: CrsContext, processor: CommandProcessor) -> py_trees.behaviour.Behaviour:
    """The whole CRS tree of Fig. 13 for ``ctx``'s mission."""
    work = build_tower(ctx)
    tower = Fallback(
        "Tower",
        memory=False,
        children=[TowerBuilt(ctx), HoldWhilePaused(ctx, work), RaiseFault(ctx, work)],
    )
    return Sequence(
        "CRS",
        memory=False,
        children=[
            InitialiseBlackboard(ctx),
            ProcessGroundCommand(processor),
            fault_check(ctx),
            BoardFlag(ctx, "Started?", "started"),
            LifterLinkWatch(ctx, processor),
            tower,
        ],
    )


__all__ = [
    "HoldWhilePaused",
    "InitialiseBlackboard",
    "add_cross_frame",
    "add_diagonal",
    "add_foundation_rivets",
    "add_vertical",
    "bay_subtree",
    "bay_test",
    "build_bay",
    "build_crs_tree",
    "build_tower",
    "fault_check",
    "index_payload",
    "member_joints",
]
