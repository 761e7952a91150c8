"""Request checks, dispenser counts and progress merging of the ARS's mission state."""

from __future__ import annotations

import pytest
from tlt_interfaces.msg import DispenserState, MemberState, MissionProgress

from tlt_ars.mission_state import DispenserEmpty, MissionState, Request
from tlt_common.mission.schema import load_mission


@pytest.fixture
def state():
    return MissionState(load_mission("missions/two_bay.yaml"), "ars_x")


def add(member: str, kind: int = 1, bay: int = 1, position: str = "", ars: str = "ars_x") -> Request:
    return Request("add_member", member, ars, bay=bay, kind=kind, position=position)


def test_valid_requests_pass(state):
    assert state.check_request(add("bay1/vertical/x0_y0", position="x0_y0")) is None
    assert state.check_request(Request("add_cross_frame", "bay1/cross_frame", "ars_x", bay=1)) is None
    assert state.check_request(add("bay1/diagonal/face_x0", kind=2, position="face_x0")) is None


@pytest.mark.parametrize(
    ("request_", "reason", "from_mission"),
    [
        (add("bay1/vertical/nope"), "unknown member 'bay1/vertical/nope' in mission 'two_bay'", True),
        (add("bay1/vertical/x0_y0", ars="ars_y"), "addressed to 'ars_y', this is 'ars_x'", True),
        (add("bay1/cross_frame"), "is a cross_frame", True),
        (add("bay1/vertical/x0_y0", kind=2), "the request says kind 2", True),
        (add("bay1/vertical/x0_y0", position="x1_y1"), "at 'x0_y0', not 'x1_y1'", True),
        (add("bay1/vertical/x0_y0", bay=2), "belongs to bay 1, not bay 2", True),
        (add("bay2/vertical/x0_y0", bay=2), "bay 2 has not started", False),
        (Request("affix_member", "bay1/vertical/x0_y0", "ars_x", bay=1), "not placed yet", False),
        (add("bay1/vertical/x1_y1"), "member 'bay1/vertical/x1_y1' is for 'ars_y' to add, not 'ars_x'", True),
        (Request("affix_member", "bay1/vertical/x0_y1", "ars_x", bay=1), "is for 'ars_y' to affix", True),
        (Request("foundation_rivet", "foundation/x1_y0", "ars_x"), "is for 'ars_y' to rivet", True),
        (Request("affix_member", "bay1/diagonal/face_x0", "ars_x", bay=1), "not placed yet", False),
        (Request("foundation_rivet", "foundation/x0_y0", "ars_x"), "bay 2 has not started", False),
    ],
)
def test_bad_requests_say_why(state, request_, reason, from_mission):
    assert reason in state.check_request(request_)
    # The node refuses what the mission alone refuses at once, and waits for fresher progress
    # before refusing the rest.
    refusal = state.mission_refusal(request_)
    assert (refusal is not None and reason in refusal) if from_mission else refusal is None


def test_placed_members_cannot_be_added_again_and_bays_start_when_the_one_above_stands(state):
    state.mark_placed("bay1/vertical/x0_y0")
    assert "already placed" in state.check_request(add("bay1/vertical/x0_y0"))
    assert state.check_request(Request("affix_member", "bay1/vertical/x0_y0", "ars_x", bay=1)) is None
    state.mark_affixed("bay1/vertical/x0_y0")
    assert "already affixed" in state.check_request(Request("affix_member", "bay1/vertical/x0_y0", "ars_x"))
    assert not state.bay_started(2)
    for member in state.mission.bay_members(1):
        state.mark_placed(member.id)
    assert state.bay_started(2)
    assert state.check_request(add("bay2/vertical/x0_y0", bay=2)) is None


def test_dispenser_counts_go_down_and_refuse_when_empty(state):
    start = state.remaining["vertical_dispenser_x"]
    for left in range(start - 1, -1, -1):
        assert state.take_part("vertical_dispenser_x") == left
    with pytest.raises(DispenserEmpty, match="dispenser 'vertical_dispenser_x' is empty"):
        state.take_part("vertical_dispenser_x")
    state.count_discard("vertical_dispenser_x")
    assert state.discarded["vertical_dispenser_x"] == 1


def test_crs_progress_merges_and_only_ever_adds_knowledge(state):
    progress = MissionProgress(mission="two_bay", current_bay=2)
    progress.members = [
        MemberState(member_id="bay1/vertical/x0_y0", kind=1, bay=1, state=MemberState.STATE_RIVETED)
    ]
    progress.dispensers = [
        DispenserState(name="rivet_dispenser_x", part_kind="rivet", remaining=3),
        DispenserState(name="vertical_dispenser_x", part_kind="vertical", remaining=99),
    ]
    before = state.remaining["vertical_dispenser_x"]
    assert state.apply_progress(progress)
    assert state.is_placed("bay1/vertical/x0_y0")
    assert "already affixed" in state.check_request(Request("affix_member", "bay1/vertical/x0_y0", "ars_x"))
    assert state.bay_started(2)
    assert state.remaining["rivet_dispenser_x"] == 3
    assert state.remaining["vertical_dispenser_x"] == before  # a higher count never adds parts
    assert not state.apply_progress(MissionProgress(mission="another", current_bay=5))


def test_foundation_rivets_are_set_once(state):
    for member in state.mission.members:
        if member.kind != "foundation_rivet":
            state.mark_placed(member.id)
    request = Request("foundation_rivet", "foundation/x0_y0", "ars_x")
    assert state.check_request(request) is None
    state.mark_riveted("foundation/x0_y0")
    assert state.is_riveted("foundation/x0_y0")
    assert "foundation rivet 'foundation/x0_y0' is already set" in state.check_request(request)
