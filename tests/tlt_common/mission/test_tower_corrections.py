"""Corrections of the tower model from the ground: each mark and the dispenser count, taken under
the model's rules or refused with the reason and nothing changed, and persisted when taken."""

from __future__ import annotations

from pathlib import Path

import pytest

from tlt_common.mission.schema import load_mission
from tlt_common.mission.tower_model import (
    INSPECTED,
    NOT_PLACED,
    PLACED,
    RIVETED,
    TowerModel,
    TransitionRefused,
)

MISSIONS = Path(__file__).resolve().parents[3] / "missions"
V1 = "bay1/vertical/x0_y1"
V2 = "bay2/vertical/x0_y1"


@pytest.fixture
def model(tmp_path):
    return TowerModel(load_mission(MISSIONS / "two_bay.yaml"), tmp_path / "tower.json")


def _build_bay(model: TowerModel, bay: int, inspected: bool = True) -> None:
    for member in model.mission.bay_members(bay):
        model.override(member.id, INSPECTED if inspected else model.done_state(member.id))


def _snapshot(model: TowerModel) -> tuple:
    return dict(model.states), dict(model.remaining), dict(model.discarded), model.revision


def test_marked_placed_a_member_stands_fixed_in_the_tower(model, tmp_path):
    model.correct_member("bay1/cross_frame", "placed")
    model.correct_member(V1, "placed")
    assert model.state("bay1/cross_frame") == PLACED and model.state(V1) == RIVETED
    assert model.is_done(V1)
    resumed = TowerModel.open(model.mission, tmp_path / "tower.json")
    assert resumed.state(V1) == RIVETED and resumed.revision == model.revision


def test_marked_unplaced_a_member_is_built_again(model):
    model.place("bay1/cross_frame")
    model.correct_member("bay1/cross_frame", "unplaced")
    assert model.state("bay1/cross_frame") == NOT_PLACED
    assert model.next_member().id == "bay1/cross_frame"


def test_marked_discarded_a_placed_strut_goes_back_and_its_dispenser_counts_the_part(model):
    model.take_part("vertical_dispenser_x")
    model.place(V1)
    model.correct_member(V1, "discarded")
    assert model.state(V1) == NOT_PLACED
    assert model.discarded["vertical_dispenser_x"] == 1 and model.remaining["vertical_dispenser_x"] == 7


def test_marked_needing_inspection_a_member_goes_back_for_its_bay_test(model):
    _build_bay(model, 1)
    model.correct_member("bay1/cross_frame", "needs_inspection")
    assert model.state("bay1/cross_frame") == PLACED
    model.correct_member(V1, "needs_inspection")
    assert model.state(V1) == RIVETED and model.bays_built() == 1


def test_a_dispenser_count_is_set(model, tmp_path):
    model.set_remaining("vertical_dispenser_x", 5)
    assert model.remaining["vertical_dispenser_x"] == 5
    assert TowerModel.open(model.mission, tmp_path / "tower.json").remaining["vertical_dispenser_x"] == 5


@pytest.mark.parametrize(
    ("prepare", "member", "mark", "reason"),
    [
        (None, "bay9/nothing", "placed", "unknown member 'bay9/nothing'"),
        (None, V1, "levitating", "unknown mark 'levitating'"),
        (lambda m: m.override(V1, RIVETED), V1, "placed", f"'{V1}' is already placed (RIVETED)"),
        (None, V2, "placed", "bay 1 is not built ('bay1/cross_frame' is NOT_PLACED): a member of bay 2"),
        (None, V1, "unplaced", f"'{V1}' is already NOT_PLACED"),
        (
            lambda m: (_build_bay(m, 1), m.place("bay2/cross_frame")),
            V1,
            "unplaced",
            "bay 2 stands on bay 1 ('bay2/cross_frame' is PLACED): unplace those first",
        ),
        (
            lambda m: m.override(V1, RIVETED),
            V1,
            "discarded",
            "is RIVETED in the tower; mark it unplaced first",
        ),
        (None, V1, "discarded", "dispenser 'vertical_dispenser_x': 0 part(s) taken, 0 already discarded"),
        (None, V1, "needs_inspection", "is NOT_PLACED; only an inspected member can need inspection again"),
        (lambda m: m.override(V1, RIVETED), V1, "needs_inspection", "already waits for its bay's inspection"),
        (
            lambda m: (_build_bay(m, 1), m.place("bay2/cross_frame")),
            V1,
            "needs_inspection",
            "its bay can no longer be tested",
        ),
    ],
)
def test_refused_corrections_say_why_and_change_nothing(model, prepare, member, mark, reason):
    if prepare is not None:
        prepare(model)
    before = _snapshot(model)
    assert reason in model.check_correction(member, mark)
    with pytest.raises(TransitionRefused) as info:
        model.correct_member(member, mark)
    assert reason in info.value.reason
    assert _snapshot(model) == before


@pytest.mark.parametrize(
    ("prepare", "dispenser", "count", "reason"),
    [
        (None, "warp_dispenser", 1, "unknown dispenser 'warp_dispenser'"),
        (None, "vertical_dispenser_x", -1, "a dispenser count is a whole number of parts, 0 or more"),
        (None, "vertical_dispenser_x", 2.5, "a dispenser count is a whole number of parts"),
        (None, "vertical_dispenser_x", True, "a dispenser count is a whole number of parts"),
        (None, "vertical_dispenser_x", 9, "can hold at most 8 part(s) (8 loaded, 0 discarded)"),
        (
            lambda m: (m.take_part("vertical_dispenser_x", 2), m.discard_part("vertical_dispenser_x")),
            "vertical_dispenser_x",
            8,
            "can hold at most 7 part(s) (8 loaded, 1 discarded)",
        ),
        (None, "vertical_dispenser_x", 8, "already holds 8 part(s)"),
    ],
)
def test_refused_dispenser_counts_say_why_and_change_nothing(model, prepare, dispenser, count, reason):
    if prepare is not None:
        prepare(model)
    before = _snapshot(model)
    with pytest.raises(TransitionRefused) as info:
        model.set_remaining(dispenser, count)
    assert reason in info.value.reason
    assert _snapshot(model) == before
