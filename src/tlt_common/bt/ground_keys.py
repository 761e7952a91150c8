"""Where a "Set Blackboard Value" key goes (Table 1): which agent, or which part of the tower model.

The one command reaches every agent's ground-writable keys and the CRS's model of the mission,
as the paper says of it ("manipulate the state of agents' behavior trees and the CRS's model of
the mission at runtime"). The key names its target:

=============================  ==============================================================
key                            target
=============================  ==============================================================
``lifter_speed``               a key of the CRS's whitelist (``crs/lifter_speed`` too)
``ars_x/settle_s``             a key of that ARS's whitelist, forwarded by the CRS over ROS
``tower/<member id>``          a correction of that member: a string of :data:`MEMBER_MARKS`
``dispenser/<name>``           a correction of the parts that dispenser holds: an int
=============================  ==============================================================

Both ends use these names: the GSW to build keys (CLI, GUI), the CRS to route them. Each agent's
whitelist is one YAML file (:data:`WHITELISTS`); :func:`load_whitelists` reads them all, for the
ground's lists of what an operator may write.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from tlt_common.bt.writable_blackboard import KeySpec, WritableBlackboard
from tlt_common.mission.tower_model import MEMBER_MARKS
from tlt_common.ros_names import ARS_AGENTS

CRS = "crs"
TOWER = "tower"
DISPENSER = "dispenser"
AGENTS = (CRS, *ARS_AGENTS)
_CONFIG = Path(__file__).resolve().parents[3] / "config"
# The project's whitelist of each agent (the CRS and the ARSs may be pointed at others in their
# configuration files).
WHITELISTS = {
    CRS: _CONFIG / "crs" / "writable_blackboard.yaml",
    **{ars: _CONFIG / "ars" / "writable_blackboard.yaml" for ars in ARS_AGENTS},
}


@dataclass(frozen=True)
class GroundKey:
    """A key as routed: ``target`` is an agent of :data:`AGENTS`, :data:`TOWER` or
    :data:`DISPENSER`; ``name`` the agent's key, the member id or the dispenser name."""

    target: str
    name: str

    @property
    def agent(self) -> str | None:
        """The agent whose whitelist holds the key; None for a tower-model correction."""
        return self.target if self.target in AGENTS else None


def route(key: str) -> GroundKey:
    """The target of ``key``; a key with no known prefix is the CRS's."""
    head, sep, rest = key.partition("/")
    if sep and head in (*AGENTS, TOWER, DISPENSER):
        return GroundKey(head, rest)
    return GroundKey(CRS, key)


def agent_key(agent: str, name: str) -> str:
    """The ground's name of ``agent``'s key ``name`` (the CRS's keys need no prefix)."""
    return name if agent == CRS else f"{agent}/{name}"


def load_whitelists(paths: Mapping[str, str | Path] | None = None) -> dict[str, WritableBlackboard]:
    """Every agent's whitelist (``paths`` overrides :data:`WHITELISTS` per agent); ``ConfigError``
    names the file, the key and the reason of a bad one."""
    chosen = {**WHITELISTS, **(paths or {})}
    loaded: dict[Path, WritableBlackboard] = {}
    out = {}
    for agent in AGENTS:
        path = Path(chosen[agent])
        if path not in loaded:
            loaded[path] = WritableBlackboard.load(path)
        out[agent] = loaded[path]
    return out


def writable_keys(whitelists: Mapping[str, WritableBlackboard]) -> dict[str, KeySpec]:
    """Ground key -> declaration of every writable key of every agent, in agent then file order."""
    return {
        agent_key(agent, spec.name): spec
        for agent, registry in whitelists.items()
        for spec in registry.writable()
    }


def member_key(member_id: str) -> str:
    return f"{TOWER}/{member_id}"


def dispenser_key(dispenser: str) -> str:
    return f"{DISPENSER}/{dispenser}"


__all__ = [
    "AGENTS",
    "CRS",
    "DISPENSER",
    "MEMBER_MARKS",
    "TOWER",
    "WHITELISTS",
    "GroundKey",
    "agent_key",
    "dispenser_key",
    "load_whitelists",
    "member_key",
    "route",
    "writable_keys",
]
