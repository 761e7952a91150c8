"""The tower model on the ground link: one 2-bit state per member in mission build order.

States follow ``tlt_interfaces/MemberState`` (0 not placed, 1 placed, 2 riveted, 3 inspected),
packed like the tree status codec: the first member in the two high bits (7-6) of the first byte,
the next in bits 5-4, unused low bits of the last byte zero. The CRS packs (``hk_tower``), the
ground unpacks.
"""

from __future__ import annotations

from collections.abc import Sequence

NOT_PLACED, PLACED, RIVETED, INSPECTED = 0, 1, 2, 3


class TowerStateError(ValueError):
    """``member_states`` bytes that do not hold exactly the announced member count."""


def pack_member_states(states: Sequence[int]) -> bytes:
    """2 bits per member, first member in the two high bits of the first byte."""
    out = bytearray((len(states) + 3) // 4)
    for i, state in enumerate(states):
        if not 0 <= state <= 3:
            raise TowerStateError(f"member {i}: state {state} is not 0..3")
        out[i >> 2] |= state << (6 - 2 * (i & 3))
    return bytes(out)


def unpack_member_states(data: bytes, count: int) -> list[int]:
    """The states of ``count`` members; raise TowerStateError if ``data`` has the wrong length."""
    if len(data) != (count + 3) // 4:
        raise TowerStateError(f"{len(data)} state bytes cannot hold exactly {count} members")
    return [(data[i >> 2] >> (6 - 2 * (i & 3))) & 3 for i in range(count)]
