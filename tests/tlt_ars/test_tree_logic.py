"""Tree mechanics of the ARS without ROS: failure reasons, feedback step and progress, the
replace-after-discard decorator, pausing a motion so that it is planned again, where a step
left in doubt may be done again, and request data kept for a restart."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import py_trees
import pytest
from py_trees.common import Status

from tlt_ars.behaviours.end_effector import KeepData
from tlt_ars.behaviours.member_record import ArmStillThere
from tlt_ars.behaviours.parts import ReplaceDiscarded
from tlt_ars.request_data import RequestData
from tlt_ars.tree import failure_reason, progress, running_step
from tlt_common.bt.nodes import Action


class Scripted(Action):
    """Answers the statuses in ``script`` one per tick (the last one repeats); counts its starts."""

    def __init__(self, name: str, script: list[Status], reason: str = "", on_tick=None) -> None:
        super().__init__(name)
        self.script, self.reason, self.on_tick = script, reason, on_tick
        self.starts = 0
        self._i = 0

    def initialise(self) -> None:
        self.starts += 1
        self._i = 0

    def update(self) -> Status:
        status = self.script[min(self._i, len(self.script) - 1)]
        self._i += 1
        if self.on_tick:
            self.on_tick(self)
        if status == Status.FAILURE:
            return self.fail(self.reason)
        return status


def seq(name, children):
    s = py_trees.composites.Sequence(name, memory=True)
    s.add_children(children)
    return s


S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


def test_failure_reason_names_the_failing_leaf_and_its_reason():
    grab = seq("Grab Member", [Scripted("Approach", [S]), Scripted("Grasp", [F], "jaws empty")])
    branch = seq("Add Member", [seq("Load Rivet", [Scripted("Rivets Left?", [S])]), grab])
    branch.tick_once()
    assert branch.status == F
    assert failure_reason(branch) == "Add Member/Grab Member/Grasp: jaws empty"


def test_running_step_and_progress_follow_the_branch():
    branch = seq(
        "Add Member", [Scripted("A", [S]), seq("Place", [Scripted("B", [R, S]), Scripted("C", [R])])]
    )
    assert progress(branch) == 0.0 and running_step(branch) == ""
    branch.tick_once()
    assert running_step(branch) == "Add Member/Place/B"
    assert progress(branch) == 1 / 3
    branch.tick_once()
    assert running_step(branch) == "Add Member/Place/C"
    assert progress(branch) == 2 / 3


def test_replace_discarded_reruns_only_after_a_discard_and_gives_up_otherwise():
    ctx = SimpleNamespace(data=SimpleNamespace(parts_discarded=0))

    def first_part_discarded(node):  # the first part fails inspection and is thrown away
        if node.starts == 1:
            ctx.data.parts_discarded += 1
        node.script = [S]  # the replacement passes

    get = Scripted("Get Part", [S])
    inspect = Scripted("Inspect", [F], "inspection failed", on_tick=first_part_discarded)
    attempt = seq("Attempt", [get, inspect])
    deco = ReplaceDiscarded("Get Inspected", attempt, ctx)
    deco.tick_once()
    assert deco.status == R and ctx.data.parts_discarded == 1  # discarded: a replacement follows
    deco.tick_once()
    assert deco.status == S and get.starts == 2

    ctx2 = SimpleNamespace(data=SimpleNamespace(parts_discarded=0))
    broken = seq("Attempt", [Scripted("Get Part", [F], "dispenser 'd' is empty")])
    deco2 = ReplaceDiscarded("Get Inspected", broken, ctx2)
    deco2.tick_once()
    assert deco2.status == F
    assert failure_reason(deco2) == "Get Inspected/Attempt/Get Part: dispenser 'd' is empty"


def test_hold_stops_the_whole_motion_so_resume_plans_again():
    from tlt_ars.tree import ArsTree

    plan = Scripted("Plan Move", [S])
    execute = Scripted("Execute Move", [R])
    motion = seq("Move", [plan, execute])
    motion.replan_on_resume = True
    root = seq("ARS", [Scripted("Before", [S]), motion])
    fake = SimpleNamespace(root=root)
    root.tick_once()
    root.tick_once()
    assert execute.status == R and plan.starts == 1
    ArsTree.hold(fake)  # what Pause does
    assert execute.status == Status.INVALID and plan.status == Status.INVALID
    root.tick_once()  # Resume: the motion starts over with a new plan from where the arm stands
    assert plan.starts == 2 and execute.starts == 2


def test_a_step_left_in_doubt_is_done_again_only_from_where_it_began():
    began_at = (0.1, -1.2, 1.5, -1.9, -1.6, 0.3)
    arm = {"q": np.array(began_at) + 0.002}
    ctx = SimpleNamespace(data=SimpleNamespace(setting_q=began_at), arm_q=lambda: arm["q"])
    there = ArmStillThere("Arm Still There?", ctx)
    there.tick_once()
    assert there.status == S
    arm["q"] = np.array(began_at) + np.array([0, 0, 0, 0.02, 0, 0])  # moved since: a wrist turned
    there.tick_once()
    assert there.status == F and there.feedback_message == "the arm is 0.0200 rad from where the step began"
    arm["q"] = None  # no fresh joint state
    there.tick_once()
    assert there.status == F and there.feedback_message == "no fresh joint state"


def test_keep_data_writes_the_request_data_then_keeps_it_or_fails_saying_why():
    kept: list[tuple[str | None, bool]] = []
    why = {"text": None}

    def keep():
        kept.append((ctx.data.holding, ctx.data.rivet_in_gun))
        return why["text"]

    ctx = SimpleNamespace(data=RequestData(holding="vertical"), keep=keep)
    KeepData("Rivet In Gun", ctx, rivet_in_gun=True).tick_once()
    released = KeepData("Part Released", ctx, holding=None)
    why["text"] = "the state file /s/ars_x.json cannot be written: No space left on device"
    released.tick_once()
    assert kept == [("vertical", True), (None, True)]  # written before it is kept
    assert released.status == F
    assert released.feedback_message == why["text"]
    with pytest.raises(ValueError, match="Part Dropped: RequestData has no field held"):
        KeepData("Part Dropped", ctx, held=None)
