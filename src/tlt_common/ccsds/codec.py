"""Building and parsing the ground link's CCSDS Space Packets (CCSDS 133.0-B), one per datagram.

Every packet has the secondary-header flag set and this layout::

    telemetry: | primary header 6 | CDS short time 7 | key id 2 | security seq 8 | fields ... |
               | HMAC-SHA256 trailer (mac_bytes) | CRC 2 |
    command:   | primary header 6 | CDS short time 7 | key id 2 | security seq 8 | cmd id 1 |
               | parameters ... | HMAC-SHA256 trailer (mac_bytes) | CRC 2 |

Telemetry is signed with a telemetry key and commands with a command key
(:mod:`tlt_common.ccsds.tm_security`). Without a key, :func:`encode_telemetry` builds and
:func:`parse_datagram` reads telemetry without security header and trailer; only offline tools
(benches, demo archives, archive tests) use that form, the link ends never do.

The primary header and the packet are built with ``spacepackets`` (``SpacePacketHeader``,
``SpacePacket``, ``CdsShortTimestamp``); the receive side reads the three header words with one
``struct`` call for speed and the time code with ``CdsShortTimestamp.unpack_from_raw`` (the fuzz
tests check the header read against ``SpacePacketHeader.unpack``). The packet error control is
CRC-16/CCITT-FALSE over all bytes before it; the MAC covers every byte before it (primary header
included), so a changed APID, count, time, key id, sequence number, command or parameter fails
authentication.

:func:`parse_datagram` is the receive side: it never raises and returns either a :class:`Packet`
or a :class:`Rejection` with a :class:`Reason`. A packet is authenticated (and its sequence
number checked and recorded against replay) before its command id, parameters or fields are
looked at.
"""

from __future__ import annotations

import binascii
import datetime
import struct
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from spacepackets.ccsds import PacketType, SequenceFlags, SpacePacket, SpacePacketHeader
from spacepackets.ccsds.time import CdsShortTimestamp
from spacepackets.ccsds.time.common import convert_ccsds_days_to_unix_days

from tlt_common.ccsds.auth import (
    MAX_SECURITY_SEQ,
    KeyLookup,
    ReplayCheck,
    ReplayStateError,
    compute_mac,
    verify_mac,
)
from tlt_common.ccsds.definitions import CommandDef, Definitions, PacketDef
from tlt_common.ccsds.fields import FieldError, FieldLayout, decode_fields, encode_fields
from tlt_common.ccsds.reasons import Reason

PRIMARY_HEADER_LEN = 6
TIME_LEN = CdsShortTimestamp.TIMESTAMP_SIZE
SECURITY_HEADER_LEN = 10
CRC_LEN = 2
TM_MIN_LEN = PRIMARY_HEADER_LEN + TIME_LEN + CRC_LEN
_SECURITY = struct.Struct(">HQ")
_CRC = struct.Struct(">H")
_PRIMARY = struct.Struct(">HHH")
_MS_PER_DAY = 86_400_000
_UTC = datetime.UTC


def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor); check 0x29B1."""
    return binascii.crc_hqx(data, 0xFFFF)


def cds_time(unix_seconds: float) -> bytes:
    """The 7-byte CDS short time code (epoch 1958-01-01, ms of day) of a Unix time."""
    return CdsShortTimestamp.from_datetime(datetime.datetime.fromtimestamp(unix_seconds, tz=_UTC)).pack()


def _read_time(raw: bytes) -> float:
    days, ms_of_day = CdsShortTimestamp.unpack_from_raw(raw)
    if ms_of_day >= _MS_PER_DAY + 1000:  # one leap second is legal
        raise ValueError(f"millisecond of day {ms_of_day} out of range")
    return convert_ccsds_days_to_unix_days(days) * 86400.0 + ms_of_day / 1000.0


_LAYOUTS: dict[int, tuple[PacketDef, FieldLayout]] = {}


def _layout(pdef: PacketDef) -> FieldLayout:
    cached = _LAYOUTS.get(id(pdef))
    if cached is None or cached[0] is not pdef:
        cached = (pdef, FieldLayout(pdef.fields))
        _LAYOUTS[id(pdef)] = cached
    return cached[1]


@dataclass(slots=True)
class Packet:
    """A decoded packet. ``kind`` is the telemetry packet name or the command name."""

    kind: str
    apid: int
    packet_type: str  # "tm" or "tc"
    seq_count: int
    time: float
    fields: Mapping[str, Any]
    raw: bytes
    command_id: int | None = None
    key_id: int | None = None
    security_seq: int | None = None

    @property
    def ok(self) -> bool:
        return True


@dataclass(frozen=True)
class Rejection:
    """A datagram that was refused, with what could be read of its header.

    ``authenticated`` says whether the command's MAC was verified, i.e. whether ``security_seq``
    and ``command_id`` can be trusted.
    """

    reason: Reason
    detail: str
    raw: bytes
    apid: int | None = None
    packet_type: str | None = None
    seq_count: int | None = None
    key_id: int | None = None
    security_seq: int | None = None
    command_id: int | None = None
    authenticated: bool = False
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return False


ParseResult = Packet | Rejection


def _space_packet(ptype: PacketType, apid: int, seq_count: int, body_len: int) -> SpacePacketHeader:
    total = PRIMARY_HEADER_LEN + TIME_LEN + body_len + CRC_LEN
    header = SpacePacketHeader(
        packet_type=ptype,
        apid=apid,
        seq_count=seq_count,
        data_len=0,
        sec_header_flag=True,
        seq_flags=SequenceFlags.UNSEGMENTED,
    )
    header.set_data_len_from_packet_len(total)
    return header


def _finish(header: SpacePacketHeader, stamp: bytes, user_data: bytes, limit: int) -> bytes:
    body = SpacePacket(header, sec_header=stamp, user_data=user_data).pack()
    body += _CRC.pack(crc16_ccitt_false(body))
    if len(body) > limit:
        raise ValueError(f"packet of {len(body)} bytes exceeds max_packet_bytes {limit}")
    return bytes(body)


def encode_telemetry(
    defs: Definitions,
    kind: str,
    values: Mapping[str, Any],
    *,
    seq_count: int,
    timestamp: float | None = None,
    key_id: int | None = None,
    key: bytes | None = None,
    security_seq: int | None = None,
) -> bytes:
    """Build a telemetry packet of ``kind``; raise ValueError/KeyError/FieldError on bad input.

    With ``key`` (and its ``key_id`` and the packet's ``security_seq``) the packet carries the
    security header and MAC trailer; without, it is the unauthenticated form.
    """
    pdef = defs.packet(kind)
    payload = encode_fields(pdef.fields, values)
    stamp = cds_time(time.time() if timestamp is None else timestamp)
    if key is None:
        header = _space_packet(PacketType.TM, pdef.apid, seq_count, len(payload))
        return _finish(header, stamp, payload, defs.max_packet_bytes)
    if key_id is None or security_seq is None:
        raise ValueError("a signed telemetry packet needs key_id and security_seq")
    if not 0 <= security_seq <= MAX_SECURITY_SEQ:
        raise ValueError(f"security sequence {security_seq} does not fit 64 bits")
    user = _SECURITY.pack(key_id, security_seq) + payload
    header = _space_packet(PacketType.TM, pdef.apid, seq_count, len(user) + defs.mac_bytes)
    signed = SpacePacket(header, sec_header=stamp, user_data=user).pack()
    mac = compute_mac(key, bytes(signed), defs.mac_bytes)
    return _finish(header, stamp, user + mac, defs.max_packet_bytes)


def check_command(defs: Definitions, cmd: CommandDef, params: Mapping[str, Any]) -> FieldError | None:
    """Checks across parameters that the field types cannot express (actuator, state, value range)."""
    actuator_param = next((p for p in cmd.params if p.actuator), None)
    if actuator_param is None:
        return None
    name = params.get(actuator_param.name)
    actuator = defs.actuators.get(name) if isinstance(name, str) else None
    if actuator is None:
        return FieldError(
            Reason.BAD_PARAMETER_RANGE,
            actuator_param.name,
            f"unknown actuator {name!r} (known: {', '.join(defs.actuators)})",
        )
    state = params.get("state")
    if "state" in params and state not in actuator.states:
        return FieldError(
            Reason.BAD_PARAMETER_RANGE,
            "state",
            f"{state!r} is not a state of {actuator.name} ({', '.join(actuator.states)})",
        )
    value = params.get("value")
    if "state" in params and state in actuator.value_states and value is None:
        return FieldError(
            Reason.BAD_PARAMETER_RANGE,
            "value",
            f"state {state!r} of {actuator.name} needs a numeric value"
            f" ({actuator.value_minimum:g} .. {actuator.value_maximum:g} {actuator.unit})",
        )
    if value is not None:
        if actuator.value_minimum is None or actuator.value_maximum is None:
            return FieldError(Reason.BAD_PARAMETER_RANGE, "value", f"{actuator.name} takes no value")
        if "state" in params and state not in actuator.value_states:
            return FieldError(
                Reason.BAD_PARAMETER_RANGE,
                "value",
                f"state {state!r} of {actuator.name} takes no value"
                f" (only {', '.join(actuator.value_states)} does)",
            )
        if not actuator.value_minimum <= value <= actuator.value_maximum:
            return FieldError(
                Reason.BAD_PARAMETER_RANGE,
                "value",
                f"{value!r} {actuator.unit} outside [{actuator.value_minimum}, "
                f"{actuator.value_maximum}] for {actuator.name}",
            )
    return None


def encode_command(
    defs: Definitions,
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    key_id: int,
    key: bytes,
    security_seq: int,
    seq_count: int,
    timestamp: float | None = None,
    check: bool = True,
) -> bytes:
    """Build an authenticated command packet.

    With ``check`` (the default) parameters are checked as the CRS will check them and a bad one
    raises :class:`FieldError` before anything is built; ``check=False`` exists so tests can build
    packets the CRS must refuse (the wire types must still fit).
    """
    cmd = defs.command(name)
    params = dict(params or {})
    if check:
        for fd in cmd.params:
            value = params.get(fd.name)
            if fd.type in ("f32", "f64") and isinstance(value, float) and value != value:
                raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, "NaN is not a valid parameter")
        problem = check_command(defs, cmd, params)
        if problem is not None:
            raise problem
    payload = encode_fields(cmd.params, params, check=check)
    if not 0 <= security_seq <= MAX_SECURITY_SEQ:
        raise ValueError(f"security sequence {security_seq} does not fit 64 bits")
    stamp = cds_time(time.time() if timestamp is None else timestamp)
    user = _SECURITY.pack(key_id, security_seq) + bytes([cmd.id]) + payload
    body_len = len(user) + defs.mac_bytes
    header = _space_packet(PacketType.TC, defs.command_apid, seq_count, body_len)
    signed = SpacePacket(header, sec_header=stamp, user_data=user).pack()
    mac = compute_mac(key, bytes(signed), defs.mac_bytes)
    return _finish(header, stamp, user + mac, defs.max_packet_bytes)


def parse_datagram(
    data: bytes,
    defs: Definitions,
    *,
    expect: str = "tm",
    keyring: KeyLookup | None = None,
    replay: ReplayCheck | None = None,
) -> ParseResult:
    """Parse one received datagram; never raises.

    ``expect`` is ``"tc"`` on the CRS (commands only, authenticated with ``keyring``, fresh against
    ``replay`` which records the accepted number) or ``"tm"`` on the GSW (telemetry APIDs only;
    with ``keyring``, the telemetry keys, authenticated and checked against ``replay`` the same
    way; without, the unauthenticated form).
    """
    if not isinstance(data, bytes | bytearray | memoryview):
        return Rejection(Reason.MALFORMED, f"not bytes but {type(data).__name__}", b"")
    raw = bytes(data)
    try:
        return _parse(raw, defs, expect, keyring, replay)
    except ReplayStateError as exc:
        return Rejection(Reason.INTERNAL_ERROR, str(exc), raw)
    except Exception as exc:  # the parser must survive any input; report rather than crash
        return Rejection(Reason.INTERNAL_ERROR, f"{type(exc).__name__}: {exc}", raw)


def _parse(
    data: bytes, defs: Definitions, expect: str, keyring: KeyLookup | None, replay: ReplayCheck | None
) -> ParseResult:
    size = len(data)
    if size > defs.max_packet_bytes:
        return Rejection(Reason.OVERSIZED, f"{size} bytes exceeds {defs.max_packet_bytes}", data)
    if size < TM_MIN_LEN:
        return Rejection(Reason.TRUNCATED, f"{size} bytes is shorter than the minimum {TM_MIN_LEN}", data)
    # The three 16-bit words of the primary header, read in one call: this runs per received packet,
    # and SpacePacketHeader.unpack (used by the tests to cross-check) builds several objects.
    word0, word1, length_field = _PRIMARY.unpack_from(data)
    version, apid = word0 >> 13, word0 & 0x7FF
    ptype = "tc" if word0 & 0x1000 else "tm"
    seq_count = word1 & 0x3FFF
    packet_len = length_field + PRIMARY_HEADER_LEN + 1
    info = {"apid": apid, "packet_type": ptype, "seq_count": seq_count}
    if version != 0:
        return Rejection(Reason.BAD_VERSION, f"packet version {version}, expected 0", data, **info)
    if packet_len > size:
        return Rejection(
            Reason.TRUNCATED, f"header says {packet_len} bytes, datagram has {size}", data, **info
        )
    if packet_len < size:
        return Rejection(
            Reason.MALFORMED, f"{size - packet_len} trailing byte(s) after the packet", data, **info
        )
    (crc,) = _CRC.unpack_from(data, size - CRC_LEN)
    computed = crc16_ccitt_false(data[:-CRC_LEN])
    if crc != computed:
        return Rejection(Reason.BAD_CRC, f"CRC {crc:#06x}, computed {computed:#06x}", data, **info)
    if not word0 & 0x0800:
        return Rejection(Reason.MALFORMED, "secondary header flag not set", data, **info)
    if word1 >> 14 != SequenceFlags.UNSEGMENTED:
        return Rejection(Reason.MALFORMED, "segmented packets are not used on this link", data, **info)
    try:
        stamp = _read_time(data[PRIMARY_HEADER_LEN : PRIMARY_HEADER_LEN + TIME_LEN])
    except ValueError as exc:
        return Rejection(Reason.MALFORMED, f"bad CDS time code: {exc}", data, **info)
    if expect == "tc":
        return _parse_command(data, defs, stamp, info, keyring, replay)
    if ptype != "tm":
        return Rejection(Reason.WRONG_PACKET_TYPE, "a command where telemetry was expected", data, **info)
    pdef = defs.telemetry_by_apid.get(apid)
    if pdef is None:
        return Rejection(Reason.UNKNOWN_APID, f"no telemetry packet has APID {apid:#05x}", data, **info)
    start = PRIMARY_HEADER_LEN + TIME_LEN
    stop = size - CRC_LEN
    key_id = security_seq = None
    if keyring is not None:
        stop -= defs.mac_bytes
        authenticated = _authenticate(data, stop, keyring, replay, info)
        if isinstance(authenticated, Rejection):
            return authenticated
        key_id, security_seq = authenticated
        start += SECURITY_HEADER_LEN
    try:
        values, end = _layout(pdef).decode(data[:stop], start)
    except FieldError as exc:
        detail = f"{pdef.name}.{exc.field}: {exc.detail}"
        return Rejection(exc.reason, detail, data, **_signed(info, key_id, security_seq))
    if end != stop:
        detail = f"{stop - end} unexpected byte(s) after {pdef.name}"
        return Rejection(Reason.MALFORMED, detail, data, **_signed(info, key_id, security_seq))
    return Packet(
        pdef.name, apid, "tm", seq_count, stamp, values, data, key_id=key_id, security_seq=security_seq
    )


def _signed(info: dict[str, Any], key_id: int | None, security_seq: int | None) -> dict[str, Any]:
    """``info`` with the security header of an authenticated packet, if it had one."""
    if key_id is None:
        return info
    return {**info, "key_id": key_id, "security_seq": security_seq, "authenticated": True}


def _authenticate(
    data: bytes,
    mac_start: int,
    keyring: KeyLookup,
    replay: ReplayCheck | None,
    info: dict[str, Any],
    verified: Mapping[str, Any] | None = None,
) -> tuple[int, int] | Rejection:
    """Check the security header and MAC that end at ``mac_start``, then freshness against ``replay``.

    Returns (key id, security sequence), or a Rejection carrying ``info``, the header's fields and,
    once the MAC verified, ``authenticated`` and the items of ``verified`` (what the MAC vouches for).
    """
    sec_start = PRIMARY_HEADER_LEN + TIME_LEN
    if mac_start < sec_start + SECURITY_HEADER_LEN:
        return Rejection(Reason.TRUNCATED, "too short for security header and MAC", data, **info)
    key_id, security_seq = _SECURITY.unpack_from(data, sec_start)
    # The rejections' fields are put together only on failure: this runs per received packet.
    key = keyring.get(key_id)
    if key is None:
        return Rejection(
            Reason.UNKNOWN_KEY,
            f"no key with id {key_id}",
            data,
            key_id=key_id,
            security_seq=security_seq,
            **info,
        )
    if not verify_mac(key, data[:mac_start], data[mac_start : len(data) - CRC_LEN]):
        return Rejection(
            Reason.BAD_AUTH, "MAC does not verify", data, key_id=key_id, security_seq=security_seq, **info
        )
    if replay is not None and not replay.accept(key_id, security_seq):
        return Rejection(
            Reason.REPLAY,
            f"sequence {security_seq} is not above the last accepted {replay.last(key_id)}",
            data,
            key_id=key_id,
            security_seq=security_seq,
            authenticated=True,
            **{**info, **(verified or {})},
        )
    return key_id, security_seq


def _parse_command(
    data: bytes,
    defs: Definitions,
    stamp: float,
    info: dict[str, Any],
    keyring: KeyLookup | None,
    replay: ReplayCheck | None,
) -> ParseResult:
    if info["packet_type"] != "tc":
        return Rejection(Reason.WRONG_PACKET_TYPE, "telemetry where a command was expected", data, **info)
    if info["apid"] != defs.command_apid:
        return Rejection(
            Reason.UNKNOWN_APID, f"APID {info['apid']:#05x} is not the command APID", data, **info
        )
    size = len(data)
    sec_start = PRIMARY_HEADER_LEN + TIME_LEN
    mac_start = size - CRC_LEN - defs.mac_bytes
    if mac_start < sec_start + SECURITY_HEADER_LEN + 1:
        return Rejection(Reason.TRUNCATED, "too short for security header, command id and MAC", data, **info)
    cmd_pos = sec_start + SECURITY_HEADER_LEN
    info = dict(info)
    if keyring is None:
        key_id, security_seq = _SECURITY.unpack_from(data, sec_start)
        info.update(key_id=key_id, security_seq=security_seq)
        return Rejection(Reason.UNKNOWN_KEY, f"no key with id {key_id}", data, **info)
    authenticated = _authenticate(data, mac_start, keyring, replay, info, {"command_id": data[cmd_pos]})
    if isinstance(authenticated, Rejection):
        return authenticated
    key_id, security_seq = authenticated
    info.update(key_id=key_id, security_seq=security_seq, command_id=data[cmd_pos], authenticated=True)
    cmd = defs.commands_by_id.get(data[cmd_pos])
    if cmd is None:
        return Rejection(Reason.UNKNOWN_COMMAND, f"no command has id {data[cmd_pos]}", data, **info)
    try:
        params, end = decode_fields(cmd.params, data[:mac_start], cmd_pos + 1, check=True)
    except FieldError as exc:
        return Rejection(exc.reason, f"{cmd.name}.{exc.field}: {exc.detail}", data, **info)
    if end != mac_start:
        return Rejection(
            Reason.MALFORMED, f"{mac_start - end} unexpected byte(s) after {cmd.name}", data, **info
        )
    problem = check_command(defs, cmd, params)
    if problem is not None:
        return Rejection(problem.reason, f"{cmd.name}.{problem.field}: {problem.detail}", data, **info)
    return Packet(
        cmd.name,
        info["apid"],
        "tc",
        info["seq_count"],
        stamp,
        params,
        data,
        command_id=cmd.id,
        key_id=key_id,
        security_seq=security_seq,
    )


__all__ = [
    "CRC_LEN",
    "PRIMARY_HEADER_LEN",
    "TIME_LEN",
    "Packet",
    "ParseResult",
    "Rejection",
    "cds_time",
    "check_command",
    "crc16_ccitt_false",
    "encode_command",
    "encode_telemetry",
    "parse_datagram",
]
