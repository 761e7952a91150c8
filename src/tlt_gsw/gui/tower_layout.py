"""Which tower member each 2-bit state of the ``hk_tower`` packet belongs to, and where it is drawn.

``hk_tower.member_states`` carries one 2-bit state per member in mission build order (0 not
placed, 1 placed, 2 riveted, 3 inspected: ``tlt_interfaces/MemberState``), packed like the tree
status codec: the first member in the two high bits (7-6) of the first byte, the next in bits 5-4,
unused low bits of the last byte zero (``tlt_common.mission.member_states``).

The layout comes from the mission file when its member count matches the packet; otherwise from
the standard mission of the reported bay count (``tlt_common.mission.generate``: 9 members per bay
and 4 foundation rivets); otherwise the members are only numbered.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tlt_common.mission.generate import build as build_standard_mission
from tlt_common.mission.member_states import (
    INSPECTED,
    NOT_PLACED,
    PLACED,
    RIVETED,
    TowerStateError,
    pack_member_states,
    unpack_member_states,
)
from tlt_common.mission.schema import Mission, load_mission, parse_mission

STATE_LABELS = {NOT_PLACED: "not placed", PLACED: "placed", RIVETED: "riveted", INSPECTED: "inspected"}
MEMBERS_PER_STANDARD_BAY = 9
STANDARD_FOUNDATION_RIVETS = 4


@dataclass(frozen=True)
class MemberSlot:
    """One member as the tower view shows it."""

    index: int
    id: str
    kind: str  # cross_frame, vertical, diagonal, foundation_rivet; "member" when unknown
    bay: int  # 0 when unknown
    position: str
    points: tuple[tuple[float, float, float], ...]  # joint coordinates (tower frame, m)


@dataclass(frozen=True)
class TowerLayout:
    """The members in build order, and where the layout came from."""

    source: str
    bay_count: int
    members: tuple[MemberSlot, ...]

    @classmethod
    def from_mission(cls, mission: Mission, source: str | None = None) -> TowerLayout:
        slots = tuple(
            MemberSlot(i, m.id, m.kind, m.bay, m.position, tuple(xyz for _, xyz in m.joints))
            for i, m in enumerate(mission.members)
        )
        return cls(source or mission.source, mission.bay_count, slots)

    @classmethod
    def standard(cls, bays: int) -> TowerLayout:
        mission = parse_mission(build_standard_mission(f"standard_{bays}_bay", bays), "<standard layout>")
        return cls.from_mission(mission, f"standard {bays}-bay layout")

    @classmethod
    def numbered(cls, count: int) -> TowerLayout:
        slots = tuple(MemberSlot(i, f"member {i + 1}", "member", 0, "", ()) for i in range(count))
        return cls("member numbers only", 0, slots)


def choose_layout(member_count: int, bays_total: int | None, mission: Mission | None) -> TowerLayout:
    """The best layout for a packet of ``member_count`` members (see the module docstring)."""
    if mission is not None and len(mission.members) == member_count:
        return TowerLayout.from_mission(mission)
    if bays_total and member_count == MEMBERS_PER_STANDARD_BAY * bays_total + STANDARD_FOUNDATION_RIVETS:
        return TowerLayout.standard(bays_total)
    return TowerLayout.numbered(member_count)


def load_layout_mission(path: Path | None) -> Mission | None:
    """The mission file of the layout, or None when no file is configured."""
    return load_mission(path) if path is not None else None


__all__ = [
    "INSPECTED",
    "NOT_PLACED",
    "PLACED",
    "RIVETED",
    "STATE_LABELS",
    "MemberSlot",
    "TowerLayout",
    "TowerStateError",
    "choose_layout",
    "load_layout_mission",
    "pack_member_states",
    "unpack_member_states",
]
