"""hk_tower member states: packing, and which member each state belongs to."""

from __future__ import annotations

from pathlib import Path

import pytest

from tlt_common.mission.schema import load_mission
from tlt_gsw.gui.tower_layout import (
    INSPECTED,
    NOT_PLACED,
    PLACED,
    RIVETED,
    TowerLayout,
    TowerStateError,
    choose_layout,
    pack_member_states,
    unpack_member_states,
)

MISSIONS = Path(__file__).resolve().parents[3] / "missions"
TWO_BAY = load_mission(MISSIONS / "two_bay.yaml")


def test_first_member_sits_in_the_high_bits_and_states_round_trip():
    assert pack_member_states([RIVETED, PLACED, NOT_PLACED, INSPECTED, PLACED]) == bytes(
        [0b10010011, 0b01000000]
    )
    states = [i % 4 for i in range(37)]
    assert unpack_member_states(pack_member_states(states), 37) == states
    assert unpack_member_states(b"", 0) == []


def test_wrong_lengths_and_states_are_refused():
    with pytest.raises(TowerStateError, match="cannot hold exactly 5"):
        unpack_member_states(b"\x00", 5)
    with pytest.raises(TowerStateError, match="cannot hold exactly 4"):
        unpack_member_states(b"\x00\x00", 4)
    with pytest.raises(TowerStateError, match="state 4"):
        pack_member_states([0, 4])


def test_layout_from_the_mission_when_counts_match():
    layout = choose_layout(len(TWO_BAY.members), 2, TWO_BAY)
    assert layout.source == TWO_BAY.source
    assert [m.id for m in layout.members] == [m.id for m in TWO_BAY.members]
    cross = layout.members[0]
    assert cross.kind == "cross_frame" and len(cross.points) == 4 and cross.bay == 1


def test_standard_layout_matches_the_generated_missions_and_numbers_otherwise():
    standard = choose_layout(22, 2, load_mission(MISSIONS / "one_bay.yaml"))  # 13 members: not this tower
    assert standard.source.startswith("standard") and standard.bay_count == 2
    assert [m.id for m in standard.members] == [m.id for m in TWO_BAY.members]
    numbered = choose_layout(7, 2, None)
    assert numbered.bay_count == 0 and [m.id for m in numbered.members][:2] == ["member 1", "member 2"]
    assert TowerLayout.standard(3).bay_count == 3 and len(TowerLayout.standard(3).members) == 31
