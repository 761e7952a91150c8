"""A seeded corpus of hostile datagrams for either end of the ground link (issue 66's security goals).

An attacker on the link holds the public packet definitions and captures of genuine traffic, never
a key. :func:`hostile_corpus` builds, from a seed and a few genuine captures, a list of datagrams of
many kinds (:data:`CATEGORIES`, one after the other so every kind is present in any corpus of a few
dozen): truncated, padded past the size limit, with a wrong version, APID, packet type, length,
flags or time code, a bad CRC, bytes altered with the CRC recomputed, a MAC forged or made with a
guessed key, an unknown key id, replayed or renumbered captures, random bytes, a well-formed
header over a garbage body, fragments of tree definitions, packets of the other direction.

Every datagram of the corpus must be refused by the end it is aimed at (``side``): the CRS's
command port (``"crs"``; captures are commands it has already accepted) or the GSW's telemetry
port (``"gsw"``; captures are telemetry it has already accepted). A genuine capture resent as it
is must be refused as a replay, which is why the captures must have been accepted before.

The link tests throw it over real UDP (``tests/tlt_crs/ground_link/test_hostile_corpus.py``,
``tests/tlt_gsw/test_hostile_corpus.py``); :func:`main` prints a corpus's make-up.
"""

from __future__ import annotations

import argparse
import os
import random
import struct
from collections import Counter
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from typing import Any

from tlt_common.bt.shape_definition import split_definition
from tlt_common.bt.status_codec import TreeShape
from tlt_common.ccsds.auth import compute_mac
from tlt_common.ccsds.codec import (
    CRC_LEN,
    PRIMARY_HEADER_LEN,
    TIME_LEN,
    cds_time,
    crc16_ccitt_false,
    encode_command,
    encode_telemetry,
)
from tlt_common.ccsds.definitions import Definitions, load_definitions

SECURITY_AT = PRIMARY_HEADER_LEN + TIME_LEN  # key id (2) and security sequence (8) start here
_WORDS = struct.Struct(">HHH")


@dataclass(frozen=True)
class HostileDatagram:
    """One datagram of the corpus and the kind of attack it is."""

    category: str
    data: bytes


def reseal(packet: bytes | bytearray) -> bytes:
    """``packet`` with its length field and CRC made to fit its bytes (what a forger does)."""
    buf = bytearray(packet)
    if len(buf) >= PRIMARY_HEADER_LEN:
        struct.pack_into(">H", buf, 4, max(0, len(buf) - PRIMARY_HEADER_LEN - 1) & 0xFFFF)
    if len(buf) >= CRC_LEN:
        body = bytes(buf[:-CRC_LEN])
        buf[-CRC_LEN:] = struct.pack(">H", crc16_ccitt_false(body))
    return bytes(buf)


def _with_words(packet: bytes, word0: int | None = None, word1: int | None = None) -> bytes:
    """``packet`` with its first or second header word replaced, CRC recomputed."""
    old0, old1, length = _WORDS.unpack_from(packet)
    head = _WORDS.pack(old0 if word0 is None else word0, old1 if word1 is None else word1, length)
    return reseal(head + packet[PRIMARY_HEADER_LEN:])


class _Forger:
    """The attacker: the definitions, genuine captures and a seeded random source, no key."""

    def __init__(self, defs: Definitions, side: str, captures: Sequence[bytes], known_ids: Collection[int],
                 rng: random.Random) -> None:  # fmt: skip
        self.defs = defs
        self.side = side
        self.captures = [bytes(c) for c in captures]
        self.known_ids = set(known_ids)
        self.rng = rng
        self.tm_apids = sorted(defs.telemetry_by_apid)
        valid = {defs.command_apid} if side == "crs" else set(self.tm_apids)
        self.foreign_apids = [a for a in range(0x800) if a not in valid]
        self.tree_parts = split_definition(_tree_shape(rng), "crs", max_chunk_bytes=48)

    # -- building blocks ----------------------------------------------------------------------
    def capture(self) -> bytes:
        return self.rng.choice(self.captures)

    def guessed_key(self) -> bytes:
        return self.rng.randbytes(32)

    def unknown_id(self) -> int:
        while True:
            key_id = self.rng.randrange(0x10000)
            if key_id not in self.known_ids:
                return key_id

    def known_id(self) -> int:
        return self.rng.choice(sorted(self.known_ids))

    def security_seq(self) -> int:
        return self.rng.choice([0, 1, 2**63, 2**64 - 1, self.rng.randrange(2**64)])

    def forged_command(self, key_id: int) -> bytes:
        rng = self.rng
        choices: list[tuple[str, dict[str, Any]]] = [
            ("start", {}),
            ("stop", {}),
            ("pause", {}),
            ("resume", {}),
            ("switch_tm_key", {}),
            ("set_blackboard_value", {"key": "lifter_speed", "value": rng.uniform(-1e3, 1e3)}),
            ("set_blackboard_value", {"key": "tower/bay1/vertical/x0_y0", "value": "placed"}),
            ("set_actuator_state", {"actuator": "lifter", "state": "hardware_control"}),
            ("set_actuator_state", {"actuator": "camera_mounts", "state": "move", "value": 1.0}),
        ]
        name, params = rng.choice(choices)
        return encode_command(
            self.defs, name, params, key_id=key_id, key=self.guessed_key(), security_seq=self.security_seq(),
            seq_count=rng.randrange(0x4000), check=False,
        )  # fmt: skip

    def forged_telemetry(self, key_id: int | None) -> bytes:
        """A telemetry packet from the public definitions: signed with a guessed key under
        ``key_id``, or in the unauthenticated offline form when ``key_id`` is None."""
        rng = self.rng
        choices: list[tuple[str, dict[str, Any]]] = [
            ("ack", {
                "command_apid": self.defs.command_apid, "command_seq_count": rng.randrange(0x4000),
                "security_seq": rng.randrange(2**64), "command": rng.choice(["stop", "start"]),
                "stage": rng.choice(["accepted", "completed"]), "reason": "none",
                "detail": "stop completed by the CRS, all motion halted",
            }),
            ("event", {
                "severity": "info", "source": "crs.ground_link", "code": "BAY_BUILT",
                "reason": "none", "text": "bay 2 built",
            }),
            ("tree_definition", self.rng.choice(self.tree_parts).fields()),
        ]  # fmt: skip
        kind, values = rng.choice(choices)
        seq_count = rng.randrange(0x4000)
        if key_id is None:
            return encode_telemetry(self.defs, kind, values, seq_count=seq_count)
        return encode_telemetry(
            self.defs, kind, values, seq_count=seq_count, key_id=key_id, key=self.guessed_key(),
            security_seq=self.security_seq(),
        )  # fmt: skip

    def own_direction(self, key_id: int) -> bytes:
        """A forged packet of the direction the target reads."""
        return self.forged_command(key_id) if self.side == "crs" else self.forged_telemetry(key_id)

    # -- the categories -----------------------------------------------------------------------
    def truncated(self) -> bytes:
        raw = self.capture()
        return raw[: self.rng.randrange(len(raw))]

    def truncated_resealed(self) -> bytes:
        raw = self.capture()
        return reseal(raw[: self.rng.randrange(PRIMARY_HEADER_LEN + CRC_LEN, len(raw))])

    def random_bytes(self) -> bytes:
        return self.rng.randbytes(self.rng.choice([1, 7, 15, 16, 40, 64, 200, 1000, 2048, 3000]))

    def oversized(self) -> bytes:
        raw = self.capture()
        size = self.rng.choice([self.defs.max_packet_bytes + 1, 3000, 4096, 9000])
        body = raw[:-CRC_LEN] + self.rng.randbytes(size - len(raw))
        return reseal(body + b"\0\0")

    def bad_version(self) -> bytes:
        raw = self.capture()
        word0 = _WORDS.unpack_from(raw)[0]
        return _with_words(raw, word0=(word0 & 0x1FFF) | (self.rng.randrange(1, 8) << 13))

    def wrong_apid(self) -> bytes:
        raw = self.capture()
        word0 = _WORDS.unpack_from(raw)[0]
        return _with_words(raw, word0=(word0 & ~0x7FF) | self.rng.choice(self.foreign_apids))

    def wrong_type(self) -> bytes:
        raw = self.capture()
        return _with_words(raw, word0=_WORDS.unpack_from(raw)[0] ^ 0x1000)

    def bad_length_field(self) -> bytes:
        buf = bytearray(self.capture())
        right = len(buf) - PRIMARY_HEADER_LEN - 1
        wrong = self.rng.choice([0, right - 1, right + 1, 0xFFFF, self.rng.randrange(0x10000)])
        struct.pack_into(">H", buf, 4, wrong if wrong != right else right + 2)
        body = bytes(buf[:-CRC_LEN])
        return body + struct.pack(">H", crc16_ccitt_false(body))

    def trailing_bytes(self) -> bytes:
        return self.capture() + self.rng.randbytes(self.rng.randrange(1, 64))

    def bad_crc(self) -> bytes:
        buf = bytearray(self.capture())
        buf[self.rng.randrange(PRIMARY_HEADER_LEN, len(buf))] ^= self.rng.randrange(1, 256)
        return bytes(buf)

    def altered_crc_recomputed(self) -> bytes:
        buf = bytearray(self.capture())
        for _ in range(self.rng.randrange(1, 5)):
            buf[self.rng.randrange(PRIMARY_HEADER_LEN, len(buf) - CRC_LEN)] ^= self.rng.randrange(1, 256)
        return reseal(buf)

    def header_flags(self) -> bytes:
        raw = self.capture()
        word0, word1, _ = _WORDS.unpack_from(raw)
        if self.rng.random() < 0.5:
            return _with_words(raw, word0=word0 & ~0x0800)  # no secondary header
        return _with_words(raw, word1=(word1 & 0x3FFF) | (self.rng.randrange(3) << 14))  # segmented

    def bad_time(self) -> bytes:
        buf = bytearray(self.capture())
        if self.rng.random() < 0.5:
            buf[PRIMARY_HEADER_LEN] = self.rng.choice([0x00, 0x41, 0x4C, 0xFF])  # P-field
        else:
            struct.pack_into(">I", buf, PRIMARY_HEADER_LEN + 3, self.rng.randrange(86_401_000, 2**32))
        return reseal(buf)

    def forged_mac(self) -> bytes:
        raw = self.capture()
        mac_at = len(raw) - CRC_LEN - self.defs.mac_bytes
        if self.rng.random() < 0.5:
            mac = self.rng.randbytes(self.defs.mac_bytes)
        else:
            mac = compute_mac(self.guessed_key(), raw[:mac_at], self.defs.mac_bytes)
        return reseal(raw[:mac_at] + mac + b"\0\0")

    def forged_from_definitions(self) -> bytes:
        if self.side == "gsw" and self.rng.random() < 0.3:
            return self.forged_telemetry(None)  # the offline, unauthenticated form
        return self.own_direction(self.known_id())

    def unknown_key(self) -> bytes:
        if self.rng.random() < 0.5:
            buf = bytearray(self.capture())
            struct.pack_into(">H", buf, SECURITY_AT, self.unknown_id())
            return reseal(buf)
        return self.own_direction(self.unknown_id())

    def replay(self) -> bytes:
        return self.capture()

    def replay_renumbered(self) -> bytes:
        """A capture with a new sequence count or security sequence, CRC recomputed."""
        buf = bytearray(self.capture())
        if self.rng.random() < 0.5:
            word1 = _WORDS.unpack_from(buf)[1]
            struct.pack_into(
                ">H", buf, 2, (word1 & 0xC000) | ((word1 + self.rng.randrange(1, 0x4000)) & 0x3FFF)
            )
        else:
            struct.pack_into(">Q", buf, SECURITY_AT + 2, self.security_seq())
        return reseal(buf)

    def garbage_body(self) -> bytes:
        """A well-formed header, a valid time code and CRC over a random body."""
        if self.side == "crs" and self.rng.random() < 0.8:
            word0 = 0x1800 | self.defs.command_apid
        else:
            word0 = 0x0800 | self.rng.choice(self.tm_apids)
        word1 = 0xC000 | self.rng.randrange(0x4000)
        body = cds_time(1.7e9 + self.rng.random() * 1e8)
        if self.rng.random() < 0.5:  # under a key id the target knows, so the MAC is checked
            body += struct.pack(">HQ", self.known_id(), self.security_seq())
        body += self.rng.randbytes(self.rng.randrange(0, 300))
        return reseal(_WORDS.pack(word0, word1, 0) + body + b"\0\0")

    def tree_definition_fragment(self) -> bytes:
        """Parts of a real compressed tree definition: forged, unsigned, cut or reshuffled."""
        choice = self.rng.randrange(4)
        if choice == 0:  # a forged part with its index and count changed
            part = self.rng.choice(self.tree_parts).fields()
            part.update(part_index=self.rng.randrange(256), part_count=self.rng.randrange(256))
            return encode_telemetry(
                self.defs, "tree_definition", part, seq_count=self.rng.randrange(0x4000),
                key_id=self.known_id(), key=self.guessed_key(), security_seq=self.security_seq(),
            )  # fmt: skip
        if choice == 1:  # unsigned, as the public definitions build it
            part = self.rng.choice(self.tree_parts).fields()
            return encode_telemetry(self.defs, "tree_definition", part, seq_count=self.rng.randrange(0x4000))
        raw = encode_telemetry(
            self.defs, "tree_definition", self.rng.choice(self.tree_parts).fields(),
            seq_count=self.rng.randrange(0x4000), key_id=self.known_id(), key=self.guessed_key(),
            security_seq=self.security_seq(),
        )  # fmt: skip
        if choice == 2:  # a fragment of a datagram
            return raw[: self.rng.randrange(len(raw))]
        return reseal(raw[: self.rng.randrange(PRIMARY_HEADER_LEN + CRC_LEN, len(raw))])

    def other_direction(self) -> bytes:
        if self.side == "crs":
            return self.forged_telemetry(self.known_id())
        return self.forged_command(self.known_id())


_CATEGORY_METHODS: dict[str, Callable[[_Forger], bytes]] = {
    "truncated": _Forger.truncated,
    "truncated_resealed": _Forger.truncated_resealed,
    "random_bytes": _Forger.random_bytes,
    "oversized": _Forger.oversized,
    "bad_version": _Forger.bad_version,
    "wrong_apid": _Forger.wrong_apid,
    "wrong_type": _Forger.wrong_type,
    "bad_length_field": _Forger.bad_length_field,
    "trailing_bytes": _Forger.trailing_bytes,
    "bad_crc": _Forger.bad_crc,
    "altered_crc_recomputed": _Forger.altered_crc_recomputed,
    "header_flags": _Forger.header_flags,
    "bad_time": _Forger.bad_time,
    "forged_mac": _Forger.forged_mac,
    "forged_from_definitions": _Forger.forged_from_definitions,
    "unknown_key": _Forger.unknown_key,
    "replay": _Forger.replay,
    "replay_renumbered": _Forger.replay_renumbered,
    "garbage_body": _Forger.garbage_body,
    "tree_definition_fragment": _Forger.tree_definition_fragment,
    "other_direction": _Forger.other_direction,
}
CATEGORIES: tuple[str, ...] = tuple(_CATEGORY_METHODS)

# The reason each end must give for the categories that admit only one (the others may fail any of
# several checks first, e.g. a resealed fragment as truncated or as failing its MAC).
REFUSED_AS: dict[str, str] = {
    "truncated": "truncated",
    "oversized": "oversized",
    "bad_version": "bad_version",
    "wrong_apid": "unknown_apid",
    "wrong_type": "wrong_packet_type",
    "trailing_bytes": "malformed",
    "bad_crc": "bad_crc",
    "header_flags": "malformed",
    "forged_mac": "bad_auth",
    "unknown_key": "unknown_key",
    "replay": "replay",
    "other_direction": "wrong_packet_type",
}


def _tree_shape(rng: random.Random) -> TreeShape:
    """A behaviour-tree shape large enough that its compressed definition takes several parts."""
    leaves = [
        {
            "depth": 2,
            "children": 0,
            "kind": "action",
            "type": "Action",
            "name": f"step {rng.randrange(10**9)}",
        }
        for _ in range(40)
    ]
    return TreeShape.from_definition(
        [
            {"depth": 0, "children": 2, "kind": "sequence", "type": "Sequence", "name": "root"},
            {"depth": 1, "children": 20, "kind": "sequence", "type": "Sequence", "name": "bay"},
            *leaves[:20],
            {"depth": 1, "children": 20, "kind": "fallback", "type": "Selector", "name": "recover"},
            *leaves[20:],
        ]
    )


def hostile_corpus(
    defs: Definitions,
    side: str,
    captures: Sequence[bytes],
    *,
    count: int = 10_000,
    seed: int = 0,
    known_key_ids: Collection[int] | None = None,
) -> list[HostileDatagram]:
    """``count`` hostile datagrams for ``side`` (``"crs"`` or ``"gsw"``), the categories in turn.

    ``captures``: genuine packets of the direction ``side`` reads, each already accepted by it.
    ``known_key_ids``: the key ids the target knows (default: those of the captures); the
    unknown-key cases use any other. The same arguments give the same corpus.
    """
    if side not in ("crs", "gsw"):
        raise ValueError(f"side must be 'crs' or 'gsw', not {side!r}")
    if not captures:
        raise ValueError("at least one genuine capture is needed")
    known = set(known_key_ids) if known_key_ids is not None else {
        struct.unpack_from(">H", raw, SECURITY_AT)[0] for raw in captures
    }  # fmt: skip
    forger = _Forger(defs, side, captures, known, random.Random(seed))
    methods = list(_CATEGORY_METHODS.items())
    return [
        HostileDatagram(name, make(forger))
        for name, make in (methods[i % len(methods)] for i in range(count))
    ]


def main(argv: list[str] | None = None) -> int:
    """Print the make-up of a corpus (categories, sizes) built from freshly signed captures."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--side", choices=["crs", "gsw"], default="crs")
    parser.add_argument("--count", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    defs = load_definitions()
    key = os.urandom(32)
    if args.side == "crs":
        captures = [
            encode_command(defs, "pause", key_id=1, key=key, security_seq=seq, seq_count=seq)
            for seq in (1, 2)
        ]
    else:
        event = {"severity": "info", "source": "crs", "code": "C", "reason": "none", "text": "ok"}
        captures = [
            encode_telemetry(defs, "event", event, seq_count=seq, key_id=1, key=key, security_seq=seq)
            for seq in (1, 2)
        ]
    corpus = hostile_corpus(defs, args.side, captures, count=args.count, seed=args.seed)
    sizes = [len(item.data) for item in corpus]
    print(
        f"{len(corpus)} datagrams for the {args.side} end, seed {args.seed}, {min(sizes)}..{max(sizes)} bytes"
    )
    for category, number in Counter(item.category for item in corpus).items():
        print(f"  {category:26s} {number}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["CATEGORIES", "REFUSED_AS", "HostileDatagram", "hostile_corpus", "main", "reseal"]
