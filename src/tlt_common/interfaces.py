"""Introspection of ``tlt_interfaces``: list every message, service and action, describe their
fields, and build sample values.

There is no ``ros2 interface`` command on these machines (ros2cli is not in the wheels), so
``tlt interfaces`` stands in for it. ``sample_message`` fills every field of a message, nested
ones included, with a value derived from a seed; the interface round-trip tests use it to prove
that every field survives the trip between processes.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Iterator
from typing import Any

from rosidl_parser.definition import (
    AbstractNestedType,
    AbstractString,
    AbstractWString,
    Array,
    BasicType,
    BoundedSequence,
    NamespacedType,
)

PACKAGE = "tlt_interfaces"
KINDS = ("msg", "srv", "action")
_MARKERS = {
    "msg": ("get_fields_and_field_types",),
    "srv": ("Request", "Response"),
    "action": ("Goal", "Result"),
}

_INT_RANGES = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
    "char": (0, 2**8 - 1),
    "byte": (0, 2**8 - 1),
    "octet": (0, 2**8 - 1),
}


def iter_interfaces(package: str = PACKAGE) -> Iterator[tuple[str, str, type]]:
    """Yield ``(kind, name, class)`` for every msg, srv and action of ``package``, sorted."""
    for kind in KINDS:
        module = importlib.import_module(f"{package}.{kind}")
        for name, cls in sorted(vars(module).items()):
            if name.startswith("_") or not inspect.isclass(cls):
                continue
            # The modules also hold metaclasses; keep the generated interface classes.
            if all(hasattr(cls, attr) for attr in _MARKERS[kind]):
                yield kind, name, cls


def message_parts(kind: str, cls: type[Any]) -> dict[str, type]:
    """The message classes that make up an interface: itself, Request/Response, Goal/Result/Feedback."""
    if kind == "msg":
        return {"message": cls}
    if kind == "srv":
        return {"request": cls.Request, "response": cls.Response}
    return {"goal": cls.Goal, "result": cls.Result, "feedback": cls.Feedback}


def describe(cls: type[Any]) -> list[str]:
    """``type name`` lines for a message class's fields."""
    return [f"{ftype} {fname}" for fname, ftype in cls.get_fields_and_field_types().items()]


def _resolve(namespaced: NamespacedType) -> type:
    module = importlib.import_module(".".join(namespaced.namespaces))
    return getattr(module, namespaced.name)


def _scalar(slot: Any, seed: int) -> Any:
    if isinstance(slot, AbstractWString):
        text = f"ü{seed}"
        return text[: slot.maximum_size] if getattr(slot, "has_maximum_size", lambda: False)() else text
    if isinstance(slot, AbstractString):
        text = f"s{seed}"
        return text[: slot.maximum_size] if getattr(slot, "has_maximum_size", lambda: False)() else text
    if isinstance(slot, NamespacedType):
        return sample_message(_resolve(slot), seed)
    assert isinstance(slot, BasicType), slot
    typename = slot.typename
    if typename == "boolean":
        return seed % 3 != 0
    if typename in ("float", "double"):
        return float(seed) + 0.25
    if typename == "byte" or typename == "octet":
        return bytes([seed % 256])
    low, high = _INT_RANGES[typename]
    return low + (seed * 7919 + 1) % (high - low + 1) if low < 0 else (seed * 7919 + 1) % (high + 1)


def sample_message(cls: type[Any], seed: int = 1) -> Any:
    """An instance of ``cls`` with every field set from ``seed`` (different seeds, different values)."""
    msg = cls()
    for i, (name, slot) in enumerate(zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES, strict=True)):
        field_seed = seed * 31 + i + 1
        if isinstance(slot, AbstractNestedType):
            if isinstance(slot, Array):
                count = slot.size
            elif isinstance(slot, BoundedSequence):
                count = min(2, slot.maximum_size)
            else:
                count = 2
            setattr(msg, name, [_scalar(slot.value_type, field_seed + k) for k in range(count)])
        else:
            setattr(msg, name, _scalar(slot, field_seed))
    return msg
