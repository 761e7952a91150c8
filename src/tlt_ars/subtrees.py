"""The ARS subtrees of paper §V.C.3, Figs. 28-40, each a function that builds it on its own from
the request's parameters and the mission, so each can be ticked and tested alone. Kept as one
module over 500 lines: one builder whose subtrees call each other as the paper's figures nest
(Fig. 32 holds Figs. 33-37), read against the table below; the behaviours they use are in
``tlt_ars.behaviours``.

The pattern of §V.C.3: a hard-coded coarse approach (``poses`` in the ARS file for dispensers and
inspection; the mission's placement and joint positions for the tower), a fine approach (the
dispenser's AprilTag, or the vision pose of the part for a placement), the action (grasp, place,
load, fire), and its verification by a sensor (EE servo feedback for grasps, the EE camera for
placements and rivet loading).

==========================  =========  ================================================================
subtree                     figure     children
==========================  =========  ================================================================
Add Cross Frame             28         Get Inspected Cross Frame (Get Cross Frame, Inspect Cross Frame,
                                       replaced after a discard), Place Cross Frame
Get Cross Frame / Grab      29 / 34    Dispenser Has Parts?, Set Width (Extend Width for a diagonal)
Member                                 beside Approach (Open Grasp, Approach Dispenser, Settle, Locate
                                       Dispenser Tag), Fine Approach, Grasp (Close Grasp, Verify Grasp),
                                       Take Part, Lift Part
Inspect Cross Frame /       30 / 35    Move To Inspection, Settle, Inspection (Inspection Passed, or
Inspect Member                         Discard Part: Move To Discard, Release, Count Discard)
Place Cross Frame           31         Coarse Approach, Fine Approach, Fine Alignment, Release, Verify
                                       Placement, Placed?, Record Placed, Retreat
Add Member                  32         Load Rivet, Get Inspected Member, Place Member, Rivet Member
                                       (a diagonal's Extend Width Ahead first, commanded and not
                                       waited for)
Load Rivet                  33         Rivets Left?, Approach Rivet Dispenser, Settle, Locate Dispenser Tag,
                                       Fine Approach, Insert Gun, Take Rivet, Withdraw Gun, Verify Rivet
                                       Loaded, Rivet In Gun (after a request that left a rivet in the
                                       gun: first Rivet Still Loaded?, the camera)
Place Member                36         Coarse Approach, Fine Approach, Fine Alignment
Rivet Member                37         Fire Rivet Gun, Record Placed, Release, Retreat (Retract Width
                                       for a diagonal, commanded and not waited for); with joint
                                       verification, Count Shot before the shot, Verify Joint after
                                       the record and Settle Joint after the retreat
Verify Joint                -          Look At Joint, then Look Again while vision cannot judge
                                       (``verify_joints.looks`` in all)
Settle Joint                -          Joint Settled? or Reshoot Joint (Load Rivet, the gun looked
                                       into first; Approach Joint, Fine Approach Joint, Settle, Count
                                       Shot, Fire Rivet Gun, Verify Joint, Retreat), per reshot
Foundation Rivet            38         Load Rivet, Place Rivet (recording the rivet set)
Affix Member                39         Load Rivet, Place Rivet (recording the member affixed); one
                                       that names a joint: Reshot (Reshoot Joint), nothing recorded
Place Rivet                 40         Approach Joint (coarse), Fine Approach Joint, Settle, Rivet
                                       Member (Fire Rivet Gun, Record Riveted / Affixed, Retreat)
Finish <request>            -          Release (an added member), Retreat (Retract Width for a
                                       diagonal): the tail of a request that set its member, sent again;
                                       after a step in doubt, Arm Still There? and that step again:
                                       Rivet Member, or Let Go At Place (a cross frame)
Discard Held Part           -          Move To Discard, Release, Count Discard: first in a branch when
                                       an earlier request left a part in the gripper
==========================  =========  ================================================================

A member is recorded the moment it is set (the rivet fired, the cross frame released where it
belongs), before the Release and the Retreat, and kept in the ARS's state file: a Retreat that
fails, or an ARS killed and restarted, leaves it set all the same, and the request sent again is
finished, not run again (:class:`tlt_ars.context.ArsContext`). The step that sets the member is
marked in the file before it begins (Mark Shot before Fire Rivet Gun, Mark Release before a cross
frame is let go of at its place): a request that ends between the mark and the record (killed
then, the gun's output never seen off) may have set its member, so it is finished by that step
again from the same place (a spent gun fires empty, open jaws stay open), never by a discard that
would tear the member out of the tower nor by a new part for a place that may be taken.

Joint verification (``verify_joints`` in the ARS file; :mod:`tlt_ars.behaviours.joint_check`):
each shot into a vertical's or a diagonal's joint is looked at by the EE camera before anything
moves, and a joint seen bad gets a new rivet after the retreat. The member is recorded set before
the look, as without it; the request succeeds whatever the looks say, and its result reports the
joint (verified, failed, unverified) with the evidence, for the CRS to act on.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import py_trees

from tlt_ars.behaviours.end_effector import (
    CommandWidth,
    FireRivetGun,
    KeepData,
    MoveGrasp,
    SetWidth,
    grasp,
    release,
)
from tlt_ars.behaviours.joint_check import CountShot, JointJudged, JointSettled, LookAtJoint
from tlt_ars.behaviours.member_record import ArmStillThere, MarkSetting, RecordMember
from tlt_ars.behaviours.parts import (
    CountDiscard,
    DispenserHasParts,
    PartPassed,
    PresentPart,
    ReplaceDiscarded,
    TakePart,
)
from tlt_ars.behaviours.vision import (
    AlignmentSeen,
    LocateDispenser,
    MeasureAlignment,
    PartAligned,
    corrected_target,
    located_dispenser_targets,
    verify_rivet_loaded,
)
from tlt_ars.config import PoseSpec
from tlt_ars.context import ArsContext
from tlt_ars.motion import Settle, move
from tlt_ars.motion_planner import MotionGoal, MotionPlanner
from tlt_ars.planning.targets import Target, placement_targets, rivet_targets
from tlt_common.bt.deferred import DeferredSequence
from tlt_common.geometry.transforms import pose_matrix, rpy_matrix
from tlt_common.mission.schema import Member

Sequence = py_trees.composites.Sequence
Fallback = py_trees.composites.Selector


def _seq(name: str, children: list[py_trees.behaviour.Behaviour]) -> Sequence:
    seq = Sequence(name, memory=True)
    seq.add_children(children)
    return seq


def _fallback(name: str, children: list[py_trees.behaviour.Behaviour]) -> Fallback:
    # With memory: a fallback's earlier child (an inspection request) is not asked again while a
    # later one (the discard) runs.
    sel = Fallback(name, memory=True)
    sel.add_children(children)
    return sel


def pose_goal(spec: PoseSpec) -> MotionGoal:
    """A configured coarse pose as a motion goal."""
    if spec.joints is not None:
        return MotionGoal(joints=np.asarray(spec.joints, dtype=float))
    pose = pose_matrix(spec.position, rpy_matrix(spec.rpy))
    return MotionGoal(targets=[Target("configured pose", pose, pose)])


def back_out(ctx: ArsContext, key: str) -> MotionGoal:
    """Straight back to the pre-pose of the fine move ``key``, allowed to start in contact with the
    tower."""
    return chosen(ctx, key, use="pre_pose", contact=True)


def chosen(ctx: ArsContext, key: str, use: str = "pose", contact: bool = False) -> MotionGoal:
    """The fine move onto the candidate an earlier approach chose (``key``), or with ``use``
    ``pre_pose`` the retreat from it: the tool on the straight line between the two."""
    target = ctx.data.targets.get(key)
    if target is None:
        raise RuntimeError(f"no '{key}' target was chosen by an earlier approach")
    return MotionGoal(targets=[target], use=use, contact=contact, key=key, straight=True)


class SubtreeBuilder:
    """Builds the subtrees of one ARS; ``ctx`` and ``planner`` are shared by all of them."""

    def __init__(self, ctx: ArsContext, planner: MotionPlanner) -> None:
        self.ctx = ctx
        self.planner = planner

    def _move(self, name: str, goal) -> Sequence:
        return move(name, self.ctx, self.planner, goal)

    # ----- getting and inspecting parts (Figs. 29, 30, 34, 35) -----
    def get_part(self, name: str, dispenser: str, kind: str) -> Sequence:
        """Fig. 29 (cross frame) / Fig. 34 (member): take the top part of ``dispenser``."""
        ctx = self.ctx
        width_name = "Extend Width" if kind == "diagonal" else "Set Width"
        # The width slide moves while the arm approaches (a diagonal's 0.25 m take 16.7 s, longer
        # than the approach): the approach is planned over the slide's move (Plan), and the grasp
        # waits for both. Camera and gun a sit on the fixed side of the bar.
        approach = _seq(
            "Approach",
            [
                MoveGrasp("Open Grasp", ctx, close=False),
                self._move("Approach Dispenser", lambda: pose_goal(self._dispenser_pose(dispenser))),
                Settle("Settle", ctx),
                LocateDispenser("Locate Dispenser Tag", ctx, dispenser),
            ],
        )
        # The approach last: a Parallel's tip is its last child's, which Pause stops (ArsTree.hold).
        beside = py_trees.composites.Parallel(
            f"{width_name} Beside Approach",
            policy=py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True),
            children=[SetWidth(width_name, ctx, kind), approach],
        )
        return _seq(
            name,
            [
                DispenserHasParts("Dispenser Has Parts?", ctx, dispenser),
                beside,
                self._move(
                    "Fine Approach",
                    lambda: MotionGoal(
                        targets=located_dispenser_targets(ctx, dispenser), use="pre_pose", key="grasp"
                    ),
                ),
                self._move("Reach Part", lambda: chosen(ctx, "grasp")),
                grasp(ctx),
                TakePart("Take Part", ctx, dispenser, kind),
                self._move("Lift Part", lambda: back_out(ctx, "grasp")),
            ],
        )

    def _dispenser_pose(self, dispenser: str) -> PoseSpec:
        try:
            return self.ctx.config.dispenser_poses[dispenser]
        except KeyError:
            raise RuntimeError(f"no coarse pose configured for dispenser '{dispenser}'") from None

    def inspect_part(self, name: str, kind: str) -> Sequence:
        """Fig. 30 / Fig. 35: show the part to the CRS's camera; discard it if it fails."""
        ctx = self.ctx
        present = PresentPart("Present Part", ctx)
        passed = PartPassed("Inspection Passed", present)
        discard = self._discard("Discard Part", passed)
        return _seq(
            name,
            [
                self._move("Move To Inspection", lambda: pose_goal(ctx.config.inspection_pose_for(kind))),
                # The CRS's camera compares the part with where the arm says it holds it: seen before
                # the arm stands, a good cross frame is off by millimetres at every corner and fails.
                Settle("Settle", ctx),
                present,
                _fallback("Inspection", [passed, discard]),
            ],
        )

    def get_inspected_part(
        self, name: str, get_name: str, inspect_name: str, dispenser: str, kind: str, *, defer: bool = False
    ) -> ReplaceDiscarded:
        """Get and inspect a part; after a discard, a replacement from the same dispenser."""

        def attempt() -> Sequence:
            return _seq(
                f"{name} Attempt",
                [self.get_part(get_name, dispenser, kind), self.inspect_part(inspect_name, kind)],
            )

        return ReplaceDiscarded(name, _phase(defer)(f"{name} Attempt", attempt), self.ctx)

    # ----- placing (Figs. 31, 36) -----
    def _approach_placement(self, member: Member) -> list[py_trees.behaviour.Behaviour]:
        ctx = self.ctx
        return [
            self._move(
                "Coarse Approach",
                lambda: MotionGoal(
                    targets=placement_targets(ctx.scene, ctx.mission, member, ctx.ars),
                    use="pre_pose",
                    key="place",
                ),
            ),
            self._move("Fine Approach", lambda: chosen(ctx, "place", contact=True)),
            self.fine_alignment(),
        ]

    def measure_alignment(self, name: str) -> Sequence:
        """Measure the held or placed part with the EE cameras; a measurement that did not see it
        (one of a placed cross frame's two corner joints can be missing from a view and both there
        on a second look) is taken once more before it is judged."""
        ctx = self.ctx
        return _seq(
            name,
            [
                MeasureAlignment("Measure", ctx),
                _fallback("Seen", [AlignmentSeen("Part Seen?", ctx), MeasureAlignment("Look Again", ctx)]),
            ],
        )

    def fine_alignment(self) -> Sequence:
        """Measure the held part with the EE camera; if it is off, move it by the measured error
        and measure again."""
        ctx = self.ctx

        def correction() -> MotionGoal:
            return MotionGoal(targets=[corrected_target(ctx, "place")], contact=True)

        correct = _seq(
            "Correct Alignment",
            [
                self._move("Correct Pose", correction),
                self.measure_alignment("Measure Again"),
                PartAligned("Aligned After Correction?", ctx),
            ],
        )
        return _seq(
            "Fine Alignment",
            [
                self.measure_alignment("Measure Alignment"),
                _fallback("Align", [PartAligned("Aligned?", ctx), correct]),
            ],
        )

    def place_cross_frame(self, member: Member) -> Sequence:
        """Fig. 31: coarse approach, fine alignment, release, placement verified by the EE camera."""
        ctx = self.ctx
        transit = []
        if ctx.config.cross_frame_transit_pose is not None:
            spec = ctx.config.cross_frame_transit_pose
            transit = [self._move("Move To Transit", lambda: pose_goal(spec))]
        return _seq(
            "Place Cross Frame",
            [
                *transit,
                *self._approach_placement(member),
                self.let_go_at_place(),
            ],
        )

    def let_go_at_place(self) -> Sequence:
        """Fig. 31's end: the cross frame let go of where it belongs, seen there, recorded placed;
        the retreat."""
        ctx = self.ctx
        return _seq(
            "Let Go At Place",
            [
                MarkSetting("Mark Release", ctx, "placed"),
                release(ctx),
                # Measured before the retreat: the D405s see the frame's corner joints from the
                # grasp; from the pre-pose 0.7 m back they look at the floor in front of it.
                self.measure_alignment("Verify Placement"),
                PartAligned("Placed?", ctx),
                RecordMember("Record Placed", ctx, "placed"),
                self._move("Retreat", lambda: back_out(ctx, "place")),
            ],
        )

    def place_member(self, member: Member) -> Sequence:
        """Fig. 36: coarse approach, fine approach, fine alignment (the part stays held for its rivet)."""
        return _seq("Place Member", self._approach_placement(member))

    # ----- rivets (Figs. 33, 37, 40) -----
    def load_rivet(self, dispenser: str, *, look_first: bool = False) -> py_trees.behaviour.Behaviour:
        """Fig. 33: take a rivet into the gun; the EE camera confirms it is loaded. When an earlier
        request left a rivet in the gun, or with ``look_first`` (a reshot: a misfire leaves its
        rivet in the gun), the camera looks for it first, and only a gun seen empty goes to the
        feeder (a loaded gun pushed into it would jam)."""
        ctx = self.ctx
        load = _seq(
            "Load Rivet",
            [
                DispenserHasParts("Rivets Left?", ctx, dispenser),
                self._move("Approach Rivet Dispenser", lambda: pose_goal(self._dispenser_pose(dispenser))),
                Settle("Settle", ctx),
                LocateDispenser("Locate Dispenser Tag", ctx, dispenser),
                self._move(
                    "Fine Approach",
                    lambda: MotionGoal(
                        targets=located_dispenser_targets(ctx, dispenser), use="pre_pose", key="rivet"
                    ),
                ),
                self._move("Insert Gun", lambda: chosen(ctx, "rivet")),
                TakePart("Take Rivet", ctx, dispenser, None),
                self._move("Withdraw Gun", lambda: back_out(ctx, "rivet")),
                verify_rivet_loaded(ctx),
                KeepData("Rivet In Gun", ctx, rivet_in_gun=True),
            ],
        )
        if not (ctx.data.rivet_in_gun or look_first):
            return load
        load.name = "Load Another Rivet"
        return _fallback("Load Rivet", [verify_rivet_loaded(ctx, "Rivet Still Loaded?"), load])

    def rivet_member(
        self, kind: str, *, record: str = "placed", member: Member | None = None, joint: str = ""
    ) -> Sequence:
        """Fig. 37: fire the gun; record the member ``record``; with the member held (``record``
        placed), let go of it; retreat; for a diagonal, retract the width afterwards. The record
        comes straight after the rivet, which is what sets the member: a Release that fails, or
        an ARS killed before it, leaves a riveted member that is finished, not placed again.
        With ``joint`` (a strut's joint, verification on: :meth:`checked_joint`), the shot is
        counted, the EE camera looks at the joint right after the record (Verify Joint, before
        anything moves), and after the retreat a joint seen bad is shot again (Settle Joint)."""
        ctx = self.ctx
        counted = [CountShot("Count Shot", ctx)] if joint else []
        children: list[py_trees.behaviour.Behaviour] = [
            MarkSetting("Mark Shot", ctx, record),
            *counted,
            FireRivetGun("Fire Rivet Gun", ctx),
            RecordMember(f"Record {record.capitalize()}", ctx, record),
        ]
        if joint:
            children.append(self.verify_joint(joint))
        holding = record == "placed"
        if holding:
            children.append(release(ctx))
        children += self._retreat(kind, "place" if holding else "joint")
        if joint and member is not None and ctx.config.verify_joints["reshots"] > 0:
            children.append(self.settle_joint(member, joint))
        return _seq("Rivet Member", children)

    # ----- joint verification (paper §VI, §VII: the rivet V&V the EDU left to an operator) -----
    def checked_joint(self, member: Member, joint: str) -> str:
        """``joint`` when the ARS verifies it (``verify_joints.enabled``, a strut's joint), else ""."""
        on = self.ctx.config.verify_joints["enabled"] and member.kind in ("vertical", "diagonal")
        return joint if on else ""

    def _request_joint(self, request: str, member: Member) -> str:
        """The joint ``request`` shoots into ``member`` when the ARS verifies it, else ""."""
        step = {"add_member": "add", "affix_member": "affix"}.get(request)
        rivet = next((r for r in member.rivets if r.step == step), None)
        return self.checked_joint(member, rivet.joint) if rivet is not None else ""

    def verify_joint(self, joint: str) -> Sequence:
        """Look at ``joint`` with the EE camera (Look At Joint); a look vision cannot judge is
        taken again, ``verify_joints.looks`` looks in all. Never fails: the looks are the verdict
        (:func:`tlt_ars.behaviours.joint_check.joint_state`)."""
        ctx = self.ctx
        children: list[py_trees.behaviour.Behaviour] = [LookAtJoint("Look At Joint", ctx, joint)]
        for n in range(2, ctx.config.verify_joints["looks"] + 1):
            again = LookAtJoint(f"Look Again {n}", ctx, joint)
            children.append(_fallback(f"Judged {n}", [JointJudged("Joint Judged?", ctx), again]))
        return _seq("Verify Joint", children)

    def settle_joint(self, member: Member, joint: str) -> Sequence:
        """A joint seen bad (no head, unseated, in the wrong hole) gets a new rivet, up to
        ``verify_joints.reshots`` times: Joint Settled? or Reshoot Joint. A joint good, not
        judged, or out of reshots is left as seen (the result reports it)."""
        ctx = self.ctx
        reshots = ctx.config.verify_joints["reshots"]
        return _seq(
            "Settle Joint",
            [
                _fallback(
                    f"Settle {n}",
                    [JointSettled("Joint Settled?", ctx, reshots), self.reshoot_joint(member, joint)],
                )
                for n in range(1, reshots + 1)
            ],
        )

    def reshoot_joint(self, member: Member, joint: str) -> Sequence:
        """A new rivet into ``joint`` of the set ``member``: Load Rivet (the gun looked into first),
        Approach Joint, Fine Approach Joint, Settle, Count Shot, Fire Rivet Gun, Verify Joint,
        Retreat. Nothing is recorded: the member stays as it was set, and a second shot replaces
        the first's rivet (drilled out)."""
        ctx = self.ctx
        rivet = next((r for r in member.rivets if r.joint == joint), None)
        if rivet is None:
            raise ValueError(f"member '{member.id}' has no rivet at joint '{joint}' in the mission")
        return _seq(
            "Reshoot Joint",
            [
                self.load_rivet(rivet.dispenser, look_first=True),
                *self._approach_joint(member, joint),
                CountShot("Count Shot", ctx),
                FireRivetGun("Fire Rivet Gun", ctx),
                self.verify_joint(joint),
                self._move("Retreat", lambda: back_out(ctx, "joint")),
            ],
        )

    def _retreat(self, kind: str, key: str) -> list[py_trees.behaviour.Behaviour]:
        ctx = self.ctx
        children = [self._move("Retreat", lambda: back_out(ctx, key))]
        if kind == "diagonal":
            # Not waited for: 16.7 s that the CRS and the other ARS can use (CommandWidth).
            children.append(CommandWidth("Retract Width", ctx, "vertical"))
        return children

    def _approach_joint(self, member: Member, joint: str) -> list[py_trees.behaviour.Behaviour]:
        ctx = self.ctx
        return [
            self._move(
                "Approach Joint",
                lambda: MotionGoal(
                    targets=rivet_targets(ctx.scene, ctx.mission, member, joint, ctx.ars),
                    use="pre_pose",
                    key="joint",
                ),
            ),
            self._move("Fine Approach Joint", lambda: chosen(ctx, "joint", contact=True)),
            # Nothing held to align first, so the gun would fire the moment the controller's
            # path ends, and a near vertical's affix rivet can miss its strut end.
            Settle("Settle", ctx),
        ]

    def place_rivet(self, member: Member, joint: str, record: str) -> Sequence:
        """Fig. 40: coarse approach to the target member's joint, then the rivet as in Fig. 37,
        recording the member ``record`` (affixed, riveted)."""
        checked = self.checked_joint(member, joint)
        return _seq(
            "Place Rivet",
            [
                *self._approach_joint(member, joint),
                self.rivet_member("rivet", record=record, member=member, joint=checked),
            ],
        )

    # ----- request branches (Figs. 28, 32, 38, 39) -----
    # With ``defer`` a branch's first phase is built at once and each later one is a
    # DeferredSequence built on the tree's next tick: the CRS waits on the request's first tick.
    def add_cross_frame(self, member: Member, *, defer: bool = False) -> Sequence:
        """Fig. 28."""
        later = _phase(defer)
        return _seq(
            "Add Cross Frame",
            [
                self.get_inspected_part(
                    "Get Inspected Cross Frame",
                    "Get Cross Frame",
                    "Inspect Cross Frame",
                    member.dispenser,
                    "cross_frame",
                ),
                later("Place Cross Frame", lambda: self.place_cross_frame(member)),
            ],
        )

    def add_member(self, member: Member, *, defer: bool = False) -> Sequence:
        """Fig. 32: load a rivet, grab, inspect, place and rivet the member."""
        rivet = _rivet(member, "add")
        later = _phase(defer)
        # A diagonal's 0.25 m of width take 16.7 s, more than the dispenser approach they run
        # beside, so the arm would stand seconds at the dispenser waiting for the slide. Commanded before
        # the rivet is loaded (gun a and the camera sit on the slide's fixed side; every motion
        # meanwhile is planned over the rest of its move), Extend Width finds it there or nearer.
        diagonal = member.kind == "diagonal"
        ahead = [CommandWidth("Extend Width Ahead", self.ctx, "diagonal")] if diagonal else []
        return _seq(
            "Add Member",
            [
                *ahead,
                self.load_rivet(rivet.dispenser),
                self.get_inspected_part(
                    "Get Inspected Member",
                    "Grab Member",
                    "Inspect Member",
                    member.dispenser,
                    member.kind,
                    defer=defer,
                ),
                later("Place Member", lambda: self.place_member(member)),
                later(
                    "Rivet Member",
                    lambda: self.rivet_member(
                        member.kind, member=member, joint=self.checked_joint(member, rivet.joint)
                    ),
                ),
            ],
        )

    def affix_member(self, member: Member, *, defer: bool = False) -> Sequence:
        """Fig. 39: load a rivet and place it in the member's affix joint. A request that names a
        joint (an operator's retry of a failed joint) shoots that joint again instead: Reshot."""
        request = self.ctx.data.request
        if request is not None and request.reshot:
            return self.reshot(member, request.joint, defer=defer)
        rivet = _rivet(member, "affix")
        return _seq(
            "Affix Member",
            [
                self.load_rivet(rivet.dispenser),
                _phase(defer)("Place Rivet", lambda: self.place_rivet(member, rivet.joint, "affixed")),
            ],
        )

    def reshot(self, member: Member, joint: str, *, defer: bool = False) -> Sequence:
        """A new rivet into ``joint`` of the set ``member`` (:meth:`reshoot_joint`), looked at
        whether or not verification is on: the operator asked for this joint."""
        return _seq(
            "Reshot",
            [_phase(defer)("Reshoot Joint", lambda: self.reshoot_joint(member, joint))],
        )

    def foundation_rivet(self, member: Member, *, defer: bool = False) -> Sequence:
        """Fig. 38: like Affix Member, into the foundation joint."""
        joint = member.joints[0][0]
        return _seq(
            "Foundation Rivet",
            [
                self.load_rivet(member.dispenser),
                _phase(defer)("Place Rivet", lambda: self.place_rivet(member, joint, "riveted")),
            ],
        )

    def branch(self, request: str, member: Member, *, defer: bool = False) -> Sequence:
        """The branch for a CRS request (one of ``ros_names.ARS_ACTIONS``); with ``defer`` its
        phases after the first are built later (:func:`tlt_common.bt.deferred.build_deferred`).
        When an earlier request left a part in the gripper, the branch discards it first: its
        motions would carry it unplanned for, and its first grasp would drop it at a dispenser."""
        builders = {
            "add_cross_frame": self.add_cross_frame,
            "add_member": self.add_member,
            "affix_member": self.affix_member,
            "foundation_rivet": self.foundation_rivet,
        }
        branch = builders[request](member, defer=defer)
        if self.ctx.data.holding is not None:
            branch.insert_child(self.discard_held(), 0)
        return branch

    def discard_held(self) -> Sequence:
        """Drop the part an earlier request left in the gripper and count it discarded (its
        inspection, if it had one, no longer says how it stands)."""
        return self._discard("Discard Held Part", None)

    def _discard(self, name: str, verdict: py_trees.behaviour.Behaviour | None) -> Sequence:
        """Move To Discard, Release, Count Discard (:class:`CountDiscard` with ``verdict``)."""
        ctx = self.ctx
        return _seq(
            name,
            [
                self._move("Move To Discard", lambda: pose_goal(ctx.config.discard_pose)),
                release(ctx),
                CountDiscard("Count Discard", ctx, verdict),
            ],
        )

    def finish(self, request: str, member: Member) -> Sequence:
        """What is left of ``request`` for ``member`` after the member was set: an added member let
        go of (a grasp already open stays open), the retreat from the tower along the approach its
        fine move took (and, after a diagonal, the width retracted). A Retreat that got part of the
        way starts from where the arm stands. A joint verified by this ARS and shot but never looked
        at (the ARS killed in between) is looked at first, from where the arm stands: a view that
        cannot judge it leaves it unverified, never good."""
        key = "joint" if request in ("affix_member", "foundation_rivet") else "place"
        kind = member.kind if request == "add_member" else ""
        let_go = [release(self.ctx)] if request == "add_member" else []
        joint = self._request_joint(request, member)
        look = [self.verify_joint(joint)] if joint and not self.ctx.data.looks else []
        return _seq(_finish_name(request), [*look, *let_go, *self._retreat(kind, key)])

    def finish_in_doubt(self, request: str, member: Member) -> Sequence:
        """What is left of ``request`` for ``member`` when the step that sets it began and was never
        recorded (the ARS killed then, the gun's output never seen off): whether the member is set
        is not known, so with the arm still where that step began it is done again and the request
        ends as it would have. Rivet Member: the gun fires again (a spent gun fires empty, a loaded
        one sets its rivet), the member is recorded, let go of, retreated from. Let Go At Place (a
        cross frame): the open jaws open, the frame is looked for at its place, recorded, the arm
        retreats. Never a discard, nor a new part: the member may stand in the tower."""
        ctx = self.ctx
        if request == "add_cross_frame":
            again = self.let_go_at_place()
        else:
            kind = member.kind if request == "add_member" else "rivet"
            joint = self._request_joint(request, member)
            again = self.rivet_member(kind, record=ctx.data.setting, member=member, joint=joint)
        return _seq(_finish_name(request), [ArmStillThere("Arm Still There?", ctx), again])


def _finish_name(request: str) -> str:
    """``add_member`` -> ``Finish Add Member``."""
    return "Finish " + " ".join(w.capitalize() for w in request.split("_"))


def _phase(defer: bool) -> Callable[[str, Callable[[], Sequence]], Sequence]:
    """How a request's later phase is made: a DeferredSequence named as the phase, or at once."""
    return DeferredSequence if defer else (lambda _name, make: make())


def _rivet(member: Member, step: str):
    for r in member.rivets:
        if r.step == step:
            return r
    raise ValueError(f"member '{member.id}' has no {step} rivet in the mission")


__all__ = [
    "SubtreeBuilder",
    "back_out",
    "chosen",
    "pose_goal",
]
