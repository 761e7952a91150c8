"""Limit alarms: every field that left its limits, shown until the operator acknowledges it and it is
back within limits (the alarm list of COSMOS and Yamcs), not only coloured while it lasts.

One row per alarm (:class:`tlt_gsw.limit_events.LimitAlarm`): when it was raised, the field (and
agent), its worst level, the value and the limit it crossed, the field's newest value, and its state
(``OUT`` or ``back within limits``, acknowledged or not). Rows are coloured by their worst level
while unacknowledged. "Acknowledge" acknowledges the selected rows, "Acknowledge all" every row;
an acknowledged alarm that is back within limits leaves the list. The title counts what still
waits for an acknowledgement.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from PySide6 import QtCore, QtWidgets

from tlt_gsw.gui.style import LIMIT_COLOURS, brush, clock_text, compact
from tlt_gsw.limit_events import Key, LimitAlarm, LimitAlarms

COLUMNS = ("Raised", "Field", "Level", "Value", "Limit", "Now", "State")


def alarm_state(alarm: LimitAlarm) -> str:
    where = "OUT" if alarm.active else "back within limits"
    return f"{where}, {'acknowledged' if alarm.acknowledged else 'NOT acknowledged'}"


class LimitAlarmPanel(QtWidgets.QGroupBox):
    """The alarm list of ``alarms``; :meth:`show_alarms` redraws it (after every change).
    ``current(key)`` is a field's newest value (None: the value of the alarm's last change)."""

    def __init__(
        self,
        alarms: LimitAlarms,
        current: Callable[[Key], Any] | None = None,
        on_acknowledged: Callable[[], None] | None = None,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__("Limit alarms", parent)
        self.alarms = alarms
        self.current = current
        self.on_acknowledged = on_acknowledged
        self._rows: list[LimitAlarm] = []
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        buttons = QtWidgets.QHBoxLayout()
        self.ack_selected = QtWidgets.QPushButton("Acknowledge")
        self.ack_selected.setObjectName("acknowledge_alarm")
        self.ack_selected.clicked.connect(self._acknowledge_selected)
        self.ack_all = QtWidgets.QPushButton("Acknowledge all")
        self.ack_all.setObjectName("acknowledge_all_alarms")
        self.ack_all.clicked.connect(lambda: self.acknowledge(list(self._rows)))
        buttons.addWidget(self.ack_selected)
        buttons.addWidget(self.ack_all)
        buttons.addStretch(1)
        layout.addLayout(buttons)
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setObjectName("limit_alarms")
        self.table.setHorizontalHeaderLabels(COLUMNS)
        compact(self.table)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.horizontalHeader().setStretchLastSection(True)
        layout.addWidget(self.table)
        self.show_alarms()

    def show_alarms(self) -> None:
        self._rows = self.alarms.shown()
        waiting = sum(not a.acknowledged for a in self._rows)
        self.setTitle(f"Limit alarms: {waiting} not acknowledged" if waiting else "Limit alarms")
        self.setStyleSheet("QGroupBox { font-weight: bold; color: #a01010; }" if waiting else "")
        self.ack_selected.setEnabled(waiting > 0)
        self.ack_all.setEnabled(waiting > 0)
        self.table.setRowCount(len(self._rows))
        for row, alarm in enumerate(self._rows):
            worst = alarm.worst
            cells = (
                clock_text(alarm.raised.time),
                worst.name,
                str(worst.level).upper(),
                worst.value_text(),
                worst.limit_text(),
                self._now_text(alarm),
                alarm_state(alarm),
            )
            for column, text in enumerate(cells):
                item = QtWidgets.QTableWidgetItem(text)
                item.setData(QtCore.Qt.ItemDataRole.UserRole, worst.level)
                if not alarm.acknowledged and (column == 2 or alarm.active):
                    item.setBackground(brush(LIMIT_COLOURS[str(worst.level)]))
                self.table.setItem(row, column, item)
        self.table.resizeColumnsToContents()

    def _now_text(self, alarm: LimitAlarm) -> str:
        value = self.current(alarm.latest.key) if self.current is not None else None
        if not isinstance(value, int | float):
            return alarm.latest.value_text()
        unit = alarm.latest.unit
        return f"{value:.6g}" + (f" {unit}" if unit else "")

    def _acknowledge_selected(self) -> None:
        rows = sorted({index.row() for index in self.table.selectionModel().selectedRows()})
        self.acknowledge([self._rows[r] for r in rows if r < len(self._rows)])

    def acknowledge(self, alarms: list[LimitAlarm]) -> None:
        """The operator acknowledged ``alarms``."""
        for alarm in alarms:
            self.alarms.acknowledge(alarm)
        self.show_alarms()
        if self.on_acknowledged is not None:
            self.on_acknowledged()

    def has_rows(self) -> bool:
        return bool(self._rows)

    def row_texts(self) -> list[list[str]]:
        """The rows shown (tests)."""
        return [
            [item.text() if (item := self.table.item(r, c)) else "" for c in range(self.table.columnCount())]
            for r in range(self.table.rowCount())
        ]


__all__ = ["LimitAlarmPanel", "alarm_state"]
