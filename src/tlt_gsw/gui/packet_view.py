"""Packet view: the newest archived packets, and the raw bytes and fields of the one selected.

The table lists :attr:`ArchiveModel.packets` (direction, time, APID, sequence count, kind, status,
size), or, for a chosen selection (rejected, sent, one packet kind), the newest packets of that
selection read from the archive. Selecting a row reads that packet's bytes and decoded fields from the
archive and shows a hex dump (offset, 16 bytes per line, ASCII) with its fields; until a row is
selected the newest packet is shown. The view follows new packets unless "Hold" is checked or the
operator scrolled up.
"""

from __future__ import annotations

from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.archive_records import PacketSummary
from tlt_gsw.gui.style import BAD_COLOUR, clock_text, compact

COLUMNS = ("Id", "Dir", "Recorded", "APID", "Seq", "Kind", "Status", "Bytes")


def hex_dump(data: bytes, width: int = 16) -> str:
    """Offset, hex bytes and printable ASCII, ``width`` bytes per line."""
    lines = []
    for offset in range(0, len(data), width):
        chunk = data[offset : offset + width]
        text = "".join(chr(b) if 32 <= b < 127 else "." for b in chunk)
        lines.append(f"{offset:04x}  {chunk.hex(' '):<{width * 3}} {text}")
    return "\n".join(lines)


class PacketTableModel(QtCore.QAbstractTableModel):
    """A Qt table model over a snapshot of the model's newest packets."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: list[PacketSummary] = []
        self._text: dict[int, tuple[Any, ...]] = {}  # packet id -> cell texts, made once per packet

    def set_rows(self, rows: list[PacketSummary]) -> None:
        self.beginResetModel()
        self.rows = rows
        keep = {row.id for row in rows}
        self._text = {pid: text for pid, text in self._text.items() if pid in keep}
        self.endResetModel()

    def rowCount(
        self,
        parent: QtCore.QModelIndex | QtCore.QPersistentModelIndex = QtCore.QModelIndex(),  # noqa: B008
    ) -> int:
        return 0 if parent.isValid() else len(self.rows)

    def columnCount(
        self,
        parent: QtCore.QModelIndex | QtCore.QPersistentModelIndex = QtCore.QModelIndex(),  # noqa: B008
    ) -> int:
        return len(COLUMNS)

    def headerData(self, section: int, orientation: QtCore.Qt.Orientation, role: int = 0) -> Any:
        if role == QtCore.Qt.ItemDataRole.DisplayRole and orientation == QtCore.Qt.Orientation.Horizontal:
            return COLUMNS[section]
        return None

    def _cells(self, row: PacketSummary) -> tuple[Any, ...]:
        text = self._text.get(row.id)
        if text is None:
            text = (
                row.id,
                row.direction,
                clock_text(row.recorded_at),
                "-" if row.apid is None else f"{row.apid:#05x}",
                "-" if row.seq_count is None else row.seq_count,
                row.kind or "-",
                row.status,
                row.size,
            )
            self._text[row.id] = text
        return text

    def data(self, index: QtCore.QModelIndex | QtCore.QPersistentModelIndex, role: int = 0) -> Any:
        row = self.rows[index.row()]
        if role == QtCore.Qt.ItemDataRole.DisplayRole:
            return self._cells(row)[index.column()]
        if role == QtCore.Qt.ItemDataRole.BackgroundRole:
            if row.status != "ok":
                return _BAD
            if row.direction == "tx":
                return _SENT
        return None


_BAD = QtGui.QBrush(QtGui.QColor(BAD_COLOUR))
_SENT = QtGui.QBrush(QtGui.QColor("#e3ecfa"))


class PacketView(QtWidgets.QWidget):
    """Packet table above a hex/fields pane; :meth:`show_packets` refreshes the table."""

    def __init__(self, model: ArchiveModel, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        layout = QtWidgets.QVBoxLayout(self)
        row = QtWidgets.QHBoxLayout()
        self.hold = QtWidgets.QCheckBox("Hold (stop following new packets)")
        self.selection = QtWidgets.QComboBox()
        self.selection.setObjectName("packet_selection")
        self.selection.addItem("all packets", "")
        self.selection.addItem("rejected", "rejected")
        self.selection.addItem("sent (commands)", "tx")
        for kind in model.defs.telemetry:
            self.selection.addItem(kind, kind)
        self.selection.currentIndexChanged.connect(lambda _: self.show_packets(force=True))
        row.addWidget(QtWidgets.QLabel("Show"))
        row.addWidget(self.selection)
        row.addWidget(self.hold)
        row.addStretch(1)
        layout.addLayout(row)
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        self.table_model = PacketTableModel()
        self.table = QtWidgets.QTableView()
        self.table.setObjectName("packet_table")
        self.table.setModel(self.table_model)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.SingleSelection)
        compact(self.table)
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.clicked.connect(lambda index: self.select_packet(self.table_model.rows[index.row()].id))
        self.detail = QtWidgets.QPlainTextEdit()
        self.detail.setObjectName("packet_hex")
        self.detail.setReadOnly(True)
        self.detail.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.detail.setPlainText("select a packet to see its bytes")
        split.addWidget(self.table)
        split.addWidget(self.detail)
        split.setStretchFactor(0, 3)
        split.setStretchFactor(1, 2)
        layout.addWidget(split, 1)
        self.selected: int | None = None
        self._seen = 0  # newest packet id the table was last built with

    def _matches(self, packet: PacketSummary, selection: str) -> bool:
        if selection == "rejected":
            return packet.status != "ok"
        if selection == "tx":
            return packet.direction == "tx"
        return packet.kind == selection

    def show_packets(self, force: bool = False) -> None:
        """Show the newest packets (of the chosen selection); ``force`` re-reads a selection."""
        if self.hold.isChecked() and not force:
            return
        selection = self.selection.currentData()
        newest = self.model.packets[-1].id if self.model.packets else 0
        if selection:
            # A selection is its own archive query, re-run only when a matching packet arrived.
            fresh = [p for p in self.model.packets if p.id > self._seen and self._matches(p, selection)]
            if force or fresh or newest < self._seen:
                rows = self.model.query_packets(selection, self.model.packet_rows)
            else:
                rows = self.table_model.rows
        else:
            rows = list(self.model.packets)
        self._seen = newest
        bar = self.table.verticalScrollBar()
        at_bottom = bar.value() >= bar.maximum() - 2
        self.table_model.set_rows(rows)
        if at_bottom or force:
            self.table.scrollToBottom()
        if self.selected is None and rows:  # until the operator picks one: the newest
            self._show(rows[-1].id)

    def select_packet(self, packet_id: int) -> str:
        """Show packet ``packet_id``'s bytes and fields (and keep showing it); return the text shown."""
        self.selected = packet_id
        return self._show(packet_id)

    def _show(self, packet_id: int) -> str:
        raw = self.model.packet_raw(packet_id)
        if raw is None:
            text = f"packet {packet_id} is not in the archive"
        else:
            known = (*self.table_model.rows, *self.model.packets)
            summary = next((p for p in known if p.id == packet_id), None)
            head = f"packet {packet_id}"
            if summary is not None:
                head += (
                    f"  {summary.direction}  {clock_text(summary.recorded_at, with_date=True)}  "
                    f"{summary.kind or '-'}  status {summary.status}"
                )
                if summary.detail:
                    head += f" ({summary.detail})"
            fields = self.model.packet_fields(packet_id)
            shown = "\n".join(
                f"  {k} = {v.hex(' ') if isinstance(v, bytes) else v}" for k, v in fields.items()
            )
            text = f"{head}\n{len(raw)} bytes\n{hex_dump(raw)}" + (f"\nfields:\n{shown}" if fields else "")
        self.detail.setPlainText(text)
        return text


__all__ = ["PacketTableModel", "PacketView", "hex_dump"]
