"""Encoding and decoding of packet fields and command parameters, as the definitions describe them.

``encode_fields`` turns a dict of Python values into bytes; ``decode_fields`` reads them back from a
buffer at an offset. Both raise :class:`FieldError` carrying a :class:`Reason` (wrong type, out of
range, truncated, malformed) and the field's name; they never write outside the returned bytes.
Enums travel as their index and decode to their label; typed values carry a tag byte with the
tags of ``tlt_interfaces/BlackboardValue`` (0 bool, 1 int, 2 float, 3 string).
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Mapping, Sequence
from typing import Any

from tlt_common.ccsds.definitions import INTEGER_TYPES, FieldDef
from tlt_common.ccsds.reasons import Reason

_STRUCTS = {
    "u8": struct.Struct(">B"),
    "u16": struct.Struct(">H"),
    "u32": struct.Struct(">I"),
    "u64": struct.Struct(">Q"),
    "i8": struct.Struct(">b"),
    "i16": struct.Struct(">h"),
    "i32": struct.Struct(">i"),
    "i64": struct.Struct(">q"),
    "f32": struct.Struct(">f"),
    "f64": struct.Struct(">d"),
    "bool": struct.Struct(">B"),
    "enum": struct.Struct(">B"),
}
_U8 = _STRUCTS["u8"]
_U16 = _STRUCTS["u16"]
_I64 = _STRUCTS["i64"]
_F64 = _STRUCTS["f64"]
_F32_MAX = 3.4028234663852886e38

TAG_BOOL, TAG_INT, TAG_FLOAT, TAG_STRING = 0, 1, 2, 3


class FieldError(ValueError):
    """A field cannot be encoded or decoded; ``reason`` is the wire reason code."""

    def __init__(self, reason: Reason, field: str, detail: str) -> None:
        self.reason = reason
        self.field = field
        self.detail = detail
        super().__init__(f"{field}: {detail}")


def _check_number(fd: FieldDef, value: Any) -> None:
    if fd.minimum is not None and value < fd.minimum:
        raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value!r} is below the minimum {fd.minimum}")
    if fd.maximum is not None and value > fd.maximum:
        raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value!r} is above the maximum {fd.maximum}")


def _check_text(fd: FieldDef, text: str, encoded: bytes, check: bool = True) -> None:
    if len(encoded) > 255:
        raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{len(encoded)} bytes is longer than 255")
    if not check:
        return
    if fd.max_length is not None and len(encoded) > fd.max_length:
        raise FieldError(
            Reason.BAD_PARAMETER_RANGE, fd.name, f"{len(encoded)} bytes is longer than {fd.max_length}"
        )
    if fd.pattern is not None and not re.fullmatch(fd.pattern, text):
        raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{text!r} does not match {fd.pattern}")


def _encode_one(fd: FieldDef, value: Any, out: bytearray, check: bool) -> None:
    kind = fd.type
    if kind in INTEGER_TYPES:
        if not isinstance(value, int) or isinstance(value, bool):
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, fd.name, f"expected an integer, got {type(value).__name__}"
            )
        lo, hi = INTEGER_TYPES[kind]
        if not lo <= value <= hi:
            raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value} does not fit {kind}")
        if check:
            _check_number(fd, value)
        out += _STRUCTS[kind].pack(value)
    elif kind in ("f32", "f64"):
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, fd.name, f"expected a number, got {type(value).__name__}"
            )
        value = float(value)
        if kind == "f32" and math.isfinite(value) and abs(value) > _F32_MAX:
            raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value} does not fit f32")
        if check:
            _check_number(fd, value)
        out += _STRUCTS[kind].pack(value)
    elif kind == "bool":
        if not isinstance(value, bool):
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, fd.name, f"expected true or false, got {type(value).__name__}"
            )
        out.append(1 if value else 0)
    elif kind == "enum":
        labels = fd.enum or ()
        if isinstance(value, str):
            if value not in labels:
                raise FieldError(
                    Reason.BAD_PARAMETER_RANGE, fd.name, f"{value!r} is not one of {list(labels)}"
                )
            out.append(labels.index(value))
        elif isinstance(value, int) and not isinstance(value, bool):
            if not 0 <= value < len(labels):
                raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"index {value} outside {fd.enum_name}")
            out.append(value)
        else:
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, fd.name, f"expected a label, got {type(value).__name__}"
            )
    elif kind == "string":
        if not isinstance(value, str):
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, fd.name, f"expected a string, got {type(value).__name__}"
            )
        encoded = value.encode("utf-8")
        _check_text(fd, value, encoded, check)
        out.append(len(encoded))
        out += encoded
    elif kind == "bytes":
        if not isinstance(value, bytes | bytearray | memoryview):
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, fd.name, f"expected bytes, got {type(value).__name__}"
            )
        limit = fd.max_length if check and fd.max_length is not None else 0xFFFF
        if len(value) > limit:
            raise FieldError(
                Reason.BAD_PARAMETER_RANGE, fd.name, f"{len(value)} bytes is longer than {limit}"
            )
        out += _U16.pack(len(value))
        out += value
    elif kind == "value":
        _encode_value(fd, value, out, check)
    else:  # the definitions loader admits only the kinds above
        raise FieldError(Reason.INTERNAL_ERROR, fd.name, f"unknown field type {kind!r}")


def _encode_value(fd: FieldDef, value: Any, out: bytearray, check: bool) -> None:
    if isinstance(value, bool):
        out.append(TAG_BOOL)
        out.append(1 if value else 0)
    elif isinstance(value, int):
        if not INTEGER_TYPES["i64"][0] <= value <= INTEGER_TYPES["i64"][1]:
            raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value} does not fit a 64-bit integer")
        out.append(TAG_INT)
        out += _I64.pack(value)
    elif isinstance(value, float):
        if check and not math.isfinite(value):
            raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value} is not a finite number")
        out.append(TAG_FLOAT)
        out += _F64.pack(value)
    elif isinstance(value, str):
        encoded = value.encode("utf-8")
        _check_text(fd, value, encoded, check)
        out.append(TAG_STRING)
        out.append(len(encoded))
        out += encoded
    else:
        raise FieldError(
            Reason.BAD_PARAMETER_TYPE,
            fd.name,
            f"expected bool, int, float or string, got {type(value).__name__}",
        )


def encode_fields(defs: Sequence[FieldDef], values: Mapping[str, Any], *, check: bool = True) -> bytes:
    """Encode ``values`` (name -> Python value) in the order of ``defs``.

    Raises :class:`FieldError` for a missing field, an unknown extra field, a wrong type or a value
    outside its wire type or (with ``check``) its declared range, length or pattern.
    """
    known = {fd.name for fd in defs}
    for name in values:
        if name not in known:
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, name, f"unknown field (known: {', '.join(sorted(known))})"
            )
    out = bytearray()
    for fd in defs:
        value = values.get(fd.name)
        if fd.optional:
            if value is None:
                out.append(0)
                continue
            out.append(1)
        elif value is None:
            raise FieldError(Reason.BAD_PARAMETER_TYPE, fd.name, "missing value")
        _encode_one(fd, value, out, check)
    return bytes(out)


def _need(buf: bytes, offset: int, size: int, name: str) -> None:
    if offset + size > len(buf):
        raise FieldError(
            Reason.TRUNCATED, name, f"needs {size} byte(s) at offset {offset}, {len(buf) - offset} left"
        )


def _decode_text(fd: FieldDef, raw: bytes, check: bool) -> str:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FieldError(Reason.BAD_PARAMETER_TYPE, fd.name, f"not UTF-8 text: {exc.reason}") from None
    if check:
        _check_text(fd, text, raw)
    return text


def _decode_one(fd: FieldDef, buf: bytes, offset: int, check: bool) -> tuple[Any, int]:
    kind = fd.type
    packer = _STRUCTS.get(kind)
    if packer is not None:
        _need(buf, offset, packer.size, fd.name)
        (value,) = packer.unpack_from(buf, offset)
        offset += packer.size
        if kind == "bool":
            if value > 1:
                raise FieldError(
                    Reason.BAD_PARAMETER_TYPE, fd.name, f"boolean byte {value} is neither 0 nor 1"
                )
            return value == 1, offset
        if kind == "enum":
            labels = fd.enum or ()
            if value >= len(labels):
                raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"index {value} outside {fd.enum_name}")
            return labels[value], offset
        if check:
            if kind in ("f32", "f64") and not math.isfinite(value):
                raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value} is not a finite number")
            _check_number(fd, value)
        return value, offset
    if kind == "string":
        _need(buf, offset, 1, fd.name)
        size = buf[offset]
        _need(buf, offset + 1, size, fd.name)
        raw = bytes(buf[offset + 1 : offset + 1 + size])
        return _decode_text(fd, raw, check), offset + 1 + size
    if kind == "bytes":
        _need(buf, offset, 2, fd.name)
        (size,) = _U16.unpack_from(buf, offset)
        if check and fd.max_length is not None and size > fd.max_length:
            raise FieldError(
                Reason.BAD_PARAMETER_RANGE, fd.name, f"{size} bytes is longer than {fd.max_length}"
            )
        _need(buf, offset + 2, size, fd.name)
        return bytes(buf[offset + 2 : offset + 2 + size]), offset + 2 + size
    if kind == "value":
        return _decode_value(fd, buf, offset, check)
    raise FieldError(Reason.INTERNAL_ERROR, fd.name, f"unknown field type {kind!r}")


def _decode_value(fd: FieldDef, buf: bytes, offset: int, check: bool) -> tuple[Any, int]:
    _need(buf, offset, 1, fd.name)
    tag = buf[offset]
    offset += 1
    if tag == TAG_BOOL:
        _need(buf, offset, 1, fd.name)
        if buf[offset] > 1:
            raise FieldError(
                Reason.BAD_PARAMETER_TYPE, fd.name, f"boolean byte {buf[offset]} is neither 0 nor 1"
            )
        return buf[offset] == 1, offset + 1
    if tag == TAG_INT:
        _need(buf, offset, 8, fd.name)
        return _I64.unpack_from(buf, offset)[0], offset + 8
    if tag == TAG_FLOAT:
        _need(buf, offset, 8, fd.name)
        value = _F64.unpack_from(buf, offset)[0]
        if check and not math.isfinite(value):
            raise FieldError(Reason.BAD_PARAMETER_RANGE, fd.name, f"{value} is not a finite number")
        return value, offset + 8
    if tag == TAG_STRING:
        _need(buf, offset, 1, fd.name)
        size = buf[offset]
        _need(buf, offset + 1, size, fd.name)
        raw = bytes(buf[offset + 1 : offset + 1 + size])
        return _decode_text(fd, raw, check), offset + 1 + size
    raise FieldError(Reason.BAD_PARAMETER_TYPE, fd.name, f"unknown value tag {tag}")


def decode_fields(
    defs: Sequence[FieldDef], buf: bytes, offset: int = 0, *, check: bool = False
) -> tuple[dict[str, Any], int]:
    """Decode the fields of ``defs`` from ``buf`` starting at ``offset``.

    Returns the values and the offset after the last field. With ``check`` (command parameters),
    values must also lie in their declared ranges, match their patterns and be finite.
    """
    values: dict[str, Any] = {}
    for fd in defs:
        if fd.optional:
            _need(buf, offset, 1, fd.name)
            present = buf[offset]
            offset += 1
            if present > 1:
                raise FieldError(Reason.MALFORMED, fd.name, f"presence byte {present} is neither 0 nor 1")
            if not present:
                values[fd.name] = None
                continue
        values[fd.name], offset = _decode_one(fd, buf, offset, check)
    return values, offset


class FieldLayout:
    """A precomputed decoder for one packet's fields (telemetry, no range checks).

    Consecutive fixed-size fields are read with one ``struct`` call; anything unusual (too few
    bytes, an enum index or boolean byte out of range) falls back to :func:`decode_fields`, which
    raises the precise :class:`FieldError`. The result always equals ``decode_fields(defs, ...)``.
    """

    def __init__(self, defs: Sequence[FieldDef]) -> None:
        self.defs = tuple(defs)
        self._steps: list[tuple] = []
        run: list[FieldDef] = []
        for fd in self.defs:
            if fd.type in _STRUCTS and not fd.optional:
                run.append(fd)
                continue
            self._flush_run(run)
            run = []
            self._steps.append(("one", (fd,)))
        self._flush_run(run)

    def _flush_run(self, run: list[FieldDef]) -> None:
        if not run:
            return
        packer = struct.Struct(">" + "".join(_STRUCTS[fd.type].format[1:] for fd in run))
        names = tuple(fd.name for fd in run)
        post = tuple(
            (i, fd.name, fd.enum if fd.type == "enum" else None)
            for i, fd in enumerate(run)
            if fd.type in ("enum", "bool")
        )
        self._steps.append(("run", packer, names, post))

    def decode(self, buf: bytes, offset: int = 0) -> tuple[dict[str, Any], int]:
        start = offset
        values: dict[str, Any] = {}
        for step in self._steps:
            if step[0] == "one":
                more, offset = decode_fields(step[1], buf, offset)
                values.update(more)
                continue
            _, packer, names, post = step
            end = offset + packer.size
            if end > len(buf):
                return decode_fields(self.defs, buf, start)
            raw = packer.unpack_from(buf, offset)
            values.update(zip(names, raw, strict=True))
            for index, name, labels in post:
                value = raw[index]
                if labels is None:
                    if value > 1:
                        return decode_fields(self.defs, buf, start)
                    values[name] = value == 1
                else:
                    if value >= len(labels):
                        return decode_fields(self.defs, buf, start)
                    values[name] = labels[value]
            offset = end
        return values, offset


__all__ = [
    "TAG_BOOL",
    "TAG_FLOAT",
    "TAG_INT",
    "TAG_STRING",
    "FieldError",
    "FieldLayout",
    "decode_fields",
    "encode_fields",
]
