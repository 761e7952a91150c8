"""Validation of YAML configuration (launch sets, hardware maps, missions, definitions).

Every file the stack loads is checked against a declared schema before anything acts on it. An
error names the file, the key (as a dotted path, list items by index) and what was expected, so an
operator can fix the file without reading code.

A schema is a dict of key name to :class:`Field`. ``validate`` returns a new dict with defaults
filled in; it never changes its input.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

_MISSING = object()


class ConfigError(ValueError):
    """A configuration file is unreadable or does not match its schema."""

    def __init__(self, source: str | Path, key: str, reason: str) -> None:
        self.source = str(source)
        self.key = key
        self.reason = reason
        where = f"{self.source}: {key}" if key else self.source
        super().__init__(f"{where}: {reason}")


@dataclass(frozen=True)
class Field:
    """One key of a schema.

    ``kind`` is one of ``str``, ``int``, ``float``, ``bool``, ``list``, ``dict`` (nested schema in
    ``schema``), ``map`` (free string keys, each value checked by ``item``) or ``any``.
    """

    kind: str
    required: bool = True
    default: Any = _MISSING
    choices: tuple[Any, ...] | None = None
    minimum: float | None = None
    maximum: float | None = None
    item: Field | None = None
    schema: Mapping[str, Field] | None = None
    check: Callable[[Any], str | None] | None = None
    doc: str = ""
    min_items: int = 0


def opt(kind: str, default: Any = None, **kw: Any) -> Field:
    """An optional field with a default."""
    return Field(kind, required=False, default=default, **kw)


_TYPE_NAMES = {
    "str": "a string",
    "int": "an integer",
    "float": "a number",
    "bool": "true or false",
    "list": "a list",
    "dict": "a mapping",
    "map": "a mapping",
}


def _type_ok(kind: str, value: Any) -> bool:
    if kind == "any":
        return True
    if kind == "str":
        return isinstance(value, str)
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "float":
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind == "list":
        return isinstance(value, list)
    if kind in ("dict", "map"):
        return isinstance(value, dict)
    raise ValueError(f"unknown field kind {kind!r}")


def _describe(value: Any) -> str:
    if value is None:
        return "nothing"
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) < 40 else text[:37] + '...'}"


def _check_value(value: Any, spec: Field, source: str, key: str) -> Any:
    if not _type_ok(spec.kind, value):
        raise ConfigError(source, key, f"expected {_TYPE_NAMES[spec.kind]}, got {_describe(value)}")
    if spec.kind == "float":
        value = float(value)
    if spec.choices is not None and value not in spec.choices:
        allowed = ", ".join(repr(c) for c in spec.choices)
        raise ConfigError(source, key, f"expected one of {allowed}, got {value!r}")
    if spec.minimum is not None and value < spec.minimum:
        raise ConfigError(source, key, f"expected at least {spec.minimum}, got {value!r}")
    if spec.maximum is not None and value > spec.maximum:
        raise ConfigError(source, key, f"expected at most {spec.maximum}, got {value!r}")
    if spec.kind == "list":
        if len(value) < spec.min_items:
            raise ConfigError(source, key, f"expected at least {spec.min_items} item(s), got {len(value)}")
        if spec.item is not None:
            value = [_check_value(v, spec.item, source, f"{key}[{i}]") for i, v in enumerate(value)]
    elif spec.kind == "dict" and spec.schema is not None:
        value = validate(value, spec.schema, source=source, prefix=key)
    elif spec.kind == "map":
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise ConfigError(source, f"{key}.{k}", f"expected a string key, got {_describe(k)}")
            out[k] = _check_value(v, spec.item, source, f"{key}.{k}") if spec.item else v
        value = out
    if spec.check is not None:
        problem = spec.check(value)
        if problem:
            raise ConfigError(source, key, problem)
    return value


def validate(
    data: Any, schema: Mapping[str, Field], *, source: str | Path, prefix: str = ""
) -> dict[str, Any]:
    """Check ``data`` against ``schema``; return it with defaults filled in.

    Raises :class:`ConfigError` naming ``source``, the dotted key and the reason on the first
    unknown key, missing required key or value of the wrong type or range.
    """
    source = str(source)
    if not isinstance(data, dict):
        raise ConfigError(source, prefix, f"expected a mapping, got {_describe(data)}")
    unknown = [k for k in data if k not in schema]
    if unknown:
        known = ", ".join(sorted(schema))
        raise ConfigError(source, _join(prefix, str(unknown[0])), f"unknown key (known keys: {known})")
    out: dict[str, Any] = {}
    for name, spec in schema.items():
        key = _join(prefix, name)
        if name not in data:
            if spec.required:
                what = spec.doc or _TYPE_NAMES.get(spec.kind, spec.kind)
                raise ConfigError(source, key, f"missing required key ({what})")
            # A copy: callers may change what they get without changing the schema's default.
            out[name] = copy.deepcopy(spec.default)
            continue
        out[name] = _check_value(data[name], spec, source, key)
    return out


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def load_yaml(path: str | Path) -> Any:
    """Read a YAML file, turning I/O and syntax errors into :class:`ConfigError`."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(path, "", f"cannot read file: {exc.strerror or exc}") from exc
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError(path, "", f"invalid YAML: {where}{problem}") from exc


def load_validated(path: str | Path, schema: Mapping[str, Field]) -> dict[str, Any]:
    """Load a YAML file and validate it against ``schema``."""
    return validate(load_yaml(path), schema, source=path)


__all__ = ["ConfigError", "Field", "load_validated", "load_yaml", "opt", "validate"]
