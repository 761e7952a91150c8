"""Settings of the GSW GUI, from ``config/gsw/gui.yaml`` (validated on load).

Reads the refresh rate, the catch-up bound, link timeout, plot fields and window, row limits, the
mission file of the tower view and the behaviour-tree definitions. A bad file raises
:class:`ConfigError` naming the file, the key and the reason; a plot field that names no field of
the definitions file is refused the same way.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from tlt_common.ccsds.definitions import Definitions
from tlt_common.config_schema import ConfigError, Field, load_validated, opt

DEFAULT_PATH = Path(__file__).resolve().parents[3] / "config" / "gsw" / "gui.yaml"
ENV_PATH = "TLT_GSW_GUI_CONFIG"

SCHEMA = {
    "refresh_hz": Field("float", minimum=0.2, maximum=100.0),
    "max_rows_per_refresh": opt("int", 20000, minimum=100),
    "link_timeout_s": opt("float", 5.0, minimum=0.1),
    "rate_window_s": opt("float", 2.0, minimum=0.1, maximum=600.0),
    "recorder_flush_s": opt("float", 0.1, minimum=0.01, maximum=10.0),
    "plot_window_s": opt("float", 120.0, minimum=1.0),
    "plot_fields": opt("list", [], item=Field("str")),
    "packet_rows": opt("int", 500, minimum=10),
    "event_rows": opt("int", 1000, minimum=10),
    "command_rows": opt("int", 200, minimum=10),
    "mission": opt("str", ""),
    "tree_definitions": opt("map", {}, item=Field("str")),
}


@dataclass(frozen=True)
class GuiConfig:
    """Validated GUI settings (paths resolved)."""

    refresh_hz: float = 10.0
    max_rows_per_refresh: int = 20000
    link_timeout_s: float = 5.0
    rate_window_s: float = 2.0
    recorder_flush_s: float = 0.1
    plot_window_s: float = 120.0
    plot_fields: tuple[tuple[str, str], ...] = ()
    packet_rows: int = 500
    event_rows: int = 1000
    command_rows: int = 200
    mission: Path | None = None
    tree_definitions: dict[str, Path] = field(default_factory=dict)

    def with_options(self, **changes: Any) -> GuiConfig:
        return replace(self, **changes)


def _resolve(base: Path, text: str) -> Path:
    path = Path(os.path.expandvars(os.path.expanduser(text)))
    return path if path.is_absolute() else (base / path).resolve()


def parse_plot_field(
    text: str, defs: Definitions, source: str = "<option>", key: str = ""
) -> tuple[str, str]:
    """``KIND.FIELD`` to (kind, field); raise ConfigError if the definitions have no such field."""
    kind, _, name = text.partition(".")
    pdef = defs.telemetry.get(kind)
    if pdef is None or not any(f.name == name for f in pdef.fields):
        raise ConfigError(source, key, f"{text!r} is not KIND.FIELD of a telemetry field in {defs.source}")
    return kind, name


def load_gui_config(path: str | Path | None, defs: Definitions) -> GuiConfig:
    """Load ``path``, else ``$TLT_GSW_GUI_CONFIG``, else the project's ``config/gsw/gui.yaml``."""
    chosen = Path(path or os.environ.get(ENV_PATH) or DEFAULT_PATH)
    doc = load_validated(chosen, SCHEMA)
    base = chosen.resolve().parent
    plots = tuple(
        parse_plot_field(text, defs, str(chosen), f"plot_fields[{i}]")
        for i, text in enumerate(doc["plot_fields"])
    )
    return GuiConfig(
        refresh_hz=doc["refresh_hz"],
        max_rows_per_refresh=doc["max_rows_per_refresh"],
        link_timeout_s=doc["link_timeout_s"],
        rate_window_s=doc["rate_window_s"],
        recorder_flush_s=doc["recorder_flush_s"],
        plot_window_s=doc["plot_window_s"],
        plot_fields=plots,
        packet_rows=doc["packet_rows"],
        event_rows=doc["event_rows"],
        command_rows=doc["command_rows"],
        mission=_resolve(base, doc["mission"]) if doc["mission"] else None,
        tree_definitions={agent: _resolve(base, p) for agent, p in doc["tree_definitions"].items()},
    )


__all__ = ["DEFAULT_PATH", "GuiConfig", "load_gui_config", "parse_plot_field"]
