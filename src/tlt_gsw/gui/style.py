"""Colours and text formats shared by the GUI's views (one place, so every view agrees)."""

from __future__ import annotations

import datetime
from typing import Any

from py_trees.common import Status
from PySide6 import QtGui, QtWidgets

from tlt_common.bt.viewer import STATUS_COLOUR
from tlt_common.ccsds.definitions import FieldDef

LIMIT_COLOURS = {"red": "#e8736c", "yellow": "#f5d04a"}
SEVERITY_COLOURS = {
    "debug": "#eeeeee",
    "info": "#ffffff",
    "warning": "#f5d04a",
    "error": "#e8736c",
    "critical": "#b0302a",
}
SEVERITIES = ("debug", "info", "warning", "error", "critical")
STAGE_COLOURS = {
    "sent": "#dddddd",
    "accepted": "#a9cdf5",
    "rejected": "#e8736c",
    "completed": "#7bc96f",
    "failed": "#e8736c",
    "not sent": "#e8736c",
}
OK_COLOUR = "#7bc96f"
BAD_COLOUR = "#e8736c"
# A hazardous command's button: dark red and bold, and grey like any disabled button when it is
# disabled (a style sheet's colour otherwise overrides the disabled look).
HAZARDOUS_BUTTON = (
    "QPushButton { color: #a01010; font-weight: bold; }"
    " QPushButton:disabled { color: #a0a0a0; font-weight: normal; }"
)
STATUS_NAMES = {
    Status.SUCCESS: "SUCCESS",
    Status.FAILURE: "FAILURE",
    Status.RUNNING: "RUNNING",
    Status.INVALID: "not ticked",
}


def compact(table: QtWidgets.QTableView) -> None:
    """Rows one text line high, no row numbers: tables of telemetry read like a list."""
    header = table.verticalHeader()
    header.setVisible(False)
    header.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.Fixed)
    header.setDefaultSectionSize(table.fontMetrics().height() + 6)
    table.setWordWrap(False)


def brush(colour: str) -> QtGui.QBrush:
    return QtGui.QBrush(QtGui.QColor(colour))


def status_colour(status: Status) -> str:
    return STATUS_COLOUR[status]


def clock_text(t: float | None, with_date: bool = False) -> str:
    """UTC wall-clock text of a Unix time (``-`` for none)."""
    if t is None:
        return "-"
    stamp = datetime.datetime.fromtimestamp(t, tz=datetime.UTC)
    return stamp.strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] if with_date else stamp.strftime("%H:%M:%S.%f")[:-3]


def value_text(fd: FieldDef | None, value: Any) -> str:
    """A field value as operators read it (units are shown in their own column)."""
    if value is None:
        return "-"
    if isinstance(value, bytes):
        return value.hex(" ") if len(value) <= 16 else f"{value[:16].hex(' ')} ... ({len(value)} B)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.4f}" if abs(value) < 1e5 else f"{value:.4g}"
    if fd is not None and fd.type in ("u8", "u16") and "bit" in fd.description:
        return f"{value} (0b{value:0{8 if fd.type == 'u8' else 16}b})"
    return str(value)


def limit_text(pair: tuple[float, float] | None) -> str:
    return "" if pair is None else f"{pair[0]:g} .. {pair[1]:g}"


def rate_text(value: float, unit: str) -> str:
    for scale, prefix in ((1e6, "M"), (1e3, "k")):
        if value >= scale:
            return f"{value / scale:.1f} {prefix}{unit}"
    return f"{value:.1f} {unit}"


__all__ = [
    "BAD_COLOUR",
    "HAZARDOUS_BUTTON",
    "LIMIT_COLOURS",
    "OK_COLOUR",
    "SEVERITIES",
    "SEVERITY_COLOURS",
    "STAGE_COLOURS",
    "STATUS_NAMES",
    "brush",
    "clock_text",
    "compact",
    "limit_text",
    "rate_text",
    "status_colour",
    "value_text",
]
