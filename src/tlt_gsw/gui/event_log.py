"""Event log: the CRS's ``event`` packets and the datagrams the GSW rejected, with severities.

Newest at the bottom (the view follows it unless the operator scrolled up). Each row: time,
severity (coloured), source, code, reason, text. A severity filter hides everything below the
chosen level. Rows come from :attr:`ArchiveModel.events`; a replayed archive shows the same log.
"""

from __future__ import annotations

from collections.abc import Iterable

from PySide6 import QtWidgets

from tlt_gsw.gui.archive_records import EventRecord
from tlt_gsw.gui.style import SEVERITIES, SEVERITY_COLOURS, brush, clock_text, compact

COLUMNS = ("Time", "Severity", "Source", "Code", "Reason", "Text")


class EventLog(QtWidgets.QWidget):
    """Severity filter and event table; :meth:`add_events` appends, :meth:`reset` clears."""

    def __init__(self, max_rows: int, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.max_rows = max_rows
        self._events: list[EventRecord] = []
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Events, at least"))
        self.minimum = QtWidgets.QComboBox()
        self.minimum.setObjectName("event_minimum")
        self.minimum.addItems(SEVERITIES)
        self.minimum.setCurrentText("info")
        self.minimum.currentTextChanged.connect(lambda _: self._redraw())
        row.addWidget(self.minimum)
        row.addStretch(1)
        layout.addLayout(row)
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setObjectName("event_log")
        self.table.setHorizontalHeaderLabels(COLUMNS)
        compact(self.table)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setStretchLastSection(True)
        layout.addWidget(self.table)

    def _shown(self, event: EventRecord) -> bool:
        rank = SEVERITIES.index(event.severity) if event.severity in SEVERITIES else len(SEVERITIES)
        return rank >= SEVERITIES.index(self.minimum.currentText())

    def reset(self, events: Iterable[EventRecord] = ()) -> None:
        self._events = list(events)[-self.max_rows :]
        self._redraw()

    def add_events(self, events: Iterable[EventRecord]) -> None:
        new = list(events)
        if not new:
            return
        self._events.extend(new)
        dropped = len(self._events) - self.max_rows
        if dropped > 0:
            self._events = self._events[dropped:]
            self._redraw()
            return
        bar = self.table.verticalScrollBar()
        at_bottom = bar.value() >= bar.maximum() - 2
        for event in new:
            if self._shown(event):
                self._append(event)
        if at_bottom:
            self.table.scrollToBottom()

    def _redraw(self) -> None:
        self.table.setRowCount(0)
        for event in self._events:
            if self._shown(event):
                self._append(event)
        self.table.resizeColumnsToContents()
        self.table.scrollToBottom()

    def _append(self, event: EventRecord) -> None:
        row = self.table.rowCount()
        self.table.insertRow(row)
        colour = brush(SEVERITY_COLOURS.get(event.severity, "#ffffff"))
        cells = (
            clock_text(event.time),
            event.severity.upper(),
            event.source,
            event.code,
            event.reason,
            event.text,
        )
        for column, text in enumerate(cells):
            item = QtWidgets.QTableWidgetItem(text)
            if column == 1 or event.severity in ("error", "critical"):
                item.setBackground(colour)
            if event.severity == "critical":
                item.setForeground(brush("#ffffff"))
            self.table.setItem(row, column, item)

    def row_texts(self) -> list[list[str]]:
        """The rows shown (tests)."""
        return [
            [item.text() if (item := self.table.item(r, c)) else "" for c in range(self.table.columnCount())]
            for r in range(self.table.rowCount())
        ]


__all__ = ["EventLog"]
