"""Command history: each command sent and every acknowledgement stage it got, from the archive.

One row per command (newest first): when it was sent, its parameters and security sequence number,
the chain of stages (``sent -> accepted -> completed``, or ``rejected`` / ``failed`` with the
reason code and detail). The rows come from :attr:`ArchiveModel.commands`: ``tx`` command packets
matched with ``ack`` packets by security sequence number, so a replayed archive shows the same.
"""

from __future__ import annotations

from collections.abc import Iterable

from PySide6 import QtWidgets

from tlt_gsw.gui.archive_records import CommandRecord
from tlt_gsw.gui.style import STAGE_COLOURS, brush, clock_text, compact

COLUMNS = ("Sent", "Command", "Stages", "Reason", "Detail", "Parameters", "Security seq")


def stage_chain(record: CommandRecord) -> str:
    stages = (["sent"] if record.sent_at is not None else ["(not in archive)"]) + [
        a.stage for a in record.acks
    ]
    chain = " → ".join(stages)
    if record.replays_rejected:
        chain += f" ({record.replays_rejected} replayed copies rejected)"
    return chain


class CommandHistory(QtWidgets.QTableWidget):
    """Table of commands and their acknowledgement stages; :meth:`show_commands` redraws it."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(0, len(COLUMNS), parent)
        self.setObjectName("command_history")
        self.setHorizontalHeaderLabels(COLUMNS)
        compact(self)
        self.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.horizontalHeader().setStretchLastSection(True)

    def show_commands(self, records: Iterable[CommandRecord]) -> None:
        rows = sorted(records, key=lambda r: r.sent_at or (r.acks[0].time if r.acks else 0.0), reverse=True)
        self.setRowCount(len(rows))
        for i, record in enumerate(rows):
            final = next((a for a in record.acks if a.stage != "accepted"), None)
            problem = final if final is not None and final.stage in ("rejected", "failed") else None
            params = ", ".join(f"{k}={v}" for k, v in record.params.items() if v is not None)
            cells = (
                clock_text(record.sent_at if record.sent_at is not None else record.acks[0].time),
                record.name,
                stage_chain(record),
                problem.reason if problem else "",
                (problem.detail if problem else (final.detail if final else "")),
                params,
                str(record.security_seq),
            )
            colour = brush(STAGE_COLOURS.get(record.last_stage, "#ffffff"))
            for j, text in enumerate(cells):
                item = QtWidgets.QTableWidgetItem(text)
                if j == 2:
                    item.setBackground(colour)
                self.setItem(i, j, item)
        self.resizeColumnsToContents()

    def row_texts(self) -> list[list[str]]:
        """The table's text, row by row (what an operator reads; used by the tests)."""
        return [
            [item.text() if (item := self.item(r, c)) else "" for c in range(self.columnCount())]
            for r in range(self.rowCount())
        ]


__all__ = ["CommandHistory", "stage_chain"]
