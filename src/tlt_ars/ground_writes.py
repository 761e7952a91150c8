"""The ground's writes to an ARS's keys ("Set Blackboard Value", Table 1), forwarded by the CRS.

The ARS's whitelist (``config/ars/writable_blackboard.yaml``, or the file its configuration names
under ``writable_blackboard``) declares each key with its type and range and the configuration
entry it stands for (``config: arm.settle_s``): the ARS tree reads its tuning values from its
configuration each time it uses them, so an accepted write changes the running value there (and
on the py_trees blackboard, where the ARS's current values can be read), from its next use on.

:func:`load_ground_writes` checks the whitelist against the configuration when the ARS starts
(every writable key names an entry that exists and holds a value of the key's type) and raises
``ConfigError`` naming the file, the key and the reason. :meth:`GroundWrites.on_request` serves
``tlt_interfaces/SetBlackboardValue`` on ``/<ars>/set_blackboard_value``: refused with the reason,
or applied.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import py_trees

from tlt_common.bt.writable_blackboard import WritableBlackboard, WriteResult
from tlt_common.config_schema import ConfigError

_FIELDS = {0: "bool_value", 1: "int_value", 2: "float_value", 3: "string_value"}
DEFAULT_WHITELIST = Path(__file__).resolve().parents[2] / "config" / "ars" / "writable_blackboard.yaml"


class GroundWrites:
    """An ARS's whitelist bound to its running configuration (``raw``: the validated YAML)."""

    def __init__(self, registry: WritableBlackboard, raw: dict[str, Any]) -> None:
        self.registry = registry
        self._raw = raw
        for spec in registry.writable():
            py_trees.blackboard.Blackboard.set(registry.blackboard_name(spec.name), self._entry(spec.config))

    def _entry(self, config: str) -> Any:
        section, name = config.split(".")
        return self._raw[section][name]

    def value(self, key: str) -> Any:
        """The running value of ``key``."""
        return self._entry(self.registry.keys[key].config)

    def write_msg(self, key: str, value_msg: Any) -> WriteResult:
        """Check a ``tlt_interfaces/BlackboardValue`` write of ``key`` and apply it when accepted."""
        result = self.registry.write_msg(key, value_msg)
        if result.accepted:
            spec = self.registry.keys[key]
            section, name = spec.config.split(".")
            value = getattr(value_msg, _FIELDS[value_msg.type])
            self._raw[section][name] = float(value) if spec.type == "float" else value
        return result

    def on_request(self, request: Any, response: Any) -> Any:
        """The ``SetBlackboardValue`` service: accepted, or refused with the reason."""
        result = self.write_msg(request.key, request.value)
        response.accepted, response.reason = result.accepted, result.reason
        return response


def load_ground_writes(raw: dict[str, Any], path: str | Path | None = None) -> GroundWrites:
    """Load the whitelist (``path``, else the project's) and check it against the ARS configuration
    ``raw``; ``ConfigError`` names the file, the key and the reason."""
    chosen = Path(path or DEFAULT_WHITELIST)
    registry = WritableBlackboard.load(chosen)
    for spec in registry.writable():
        key = f"keys.{spec.name}.config"
        if not spec.config:
            raise ConfigError(chosen, key, "an ARS key names the configuration entry it stands for")
        section, name = spec.config.split(".")
        entry = raw.get(section)
        if not isinstance(entry, dict) or name not in entry:
            raise ConfigError(chosen, key, f"the ARS configuration has no entry {spec.config!r}")
        value = entry[name]
        kind = type(value)
        if spec.type == "float" and kind is int:
            entry[name] = float(value)
        elif kind.__name__ != spec.type:
            raise ConfigError(
                chosen, key, f"{spec.config} holds {kind.__name__} {value!r}, the key is {spec.type}"
            )
    return GroundWrites(registry, raw)


__all__ = ["DEFAULT_WHITELIST", "GroundWrites", "load_ground_writes"]
