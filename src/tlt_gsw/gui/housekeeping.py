"""Housekeeping pages generated from the definitions file, values coloured by their limits.

One tab per housekeeping packet kind of ``config/ccsds/definitions.yaml`` (every telemetry kind but
``ack``, ``event`` and ``tree_status``), one row per field in wire order: value, unit, yellow and
red ranges, description. A kind sent once per agent (a field with the ``agent`` enum, e.g.
``hk_ee.ars``) gets one value column per agent. A value outside its red range is shown on red,
outside its yellow range on yellow (:meth:`Limits.classify`), and the tab's title takes the worst
colour of its page. Adding a field to the definitions file adds its row here; nothing else to edit.
"Export CSV…" writes every packet of the shown kind, up to the display's position, to a CSV file.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from PySide6 import QtGui, QtWidgets

from tlt_common.ccsds.definitions import Definitions, PacketDef
from tlt_gsw.gui.archive_records import HousekeepingSnapshot
from tlt_gsw.gui.style import LIMIT_COLOURS, brush, clock_text, compact, limit_text, value_text

_FIXED = ("Unit", "Yellow", "Red", "Description")
_TAB_TEXT = {"red": "#c0201a", "yellow": "#a07000", None: "#000000"}


class HousekeepingPage(QtWidgets.QWidget):
    """The table of one packet kind."""

    def __init__(self, pdef: PacketDef, instance_field: str | None) -> None:
        super().__init__()
        self.pdef = pdef
        self.instance_field = instance_field
        self.rows = [f for f in pdef.fields if f.name != instance_field]
        self.instances: list[str] = []
        layout = QtWidgets.QVBoxLayout(self)
        self.header = QtWidgets.QLabel(
            f"{pdef.name} (APID {pdef.apid:#05x}): {pdef.description}  no packet yet"
        )
        self.header.setWordWrap(True)
        layout.addWidget(self.header)
        self.table = QtWidgets.QTableWidget(len(self.rows), 1 + len(_FIXED))
        self.table.setObjectName(f"hk_{pdef.name}")
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        compact(self.table)
        self.table.horizontalHeader().setStretchLastSection(True)
        self._set_headers()
        for r, fd in enumerate(self.rows):
            self.table.setItem(r, 0, QtWidgets.QTableWidgetItem(fd.name))
            limits = fd.limits
            fixed = (
                fd.unit,
                limit_text(limits.yellow) if limits else "",
                limit_text(limits.red) if limits else "",
                fd.description,
            )
            for c, text in enumerate(fixed):
                self.table.setItem(r, self._first_fixed() + c, QtWidgets.QTableWidgetItem(text))
        layout.addWidget(self.table)
        self.worst: str | None = None  # the worst limit colour of the newest values, set by the pages
        self._sized = False

    def _first_fixed(self) -> int:
        return 1 + max(1, len(self.instances))

    def _set_headers(self) -> None:
        values = [f"{self.instance_field} = {i}" for i in self.instances] or ["Value"]
        self.table.setColumnCount(1 + len(values) + len(_FIXED))
        self.table.setHorizontalHeaderLabels(["Field", *values, *_FIXED])

    def _column(self, instance: str) -> int:
        if not self.instance_field:
            return 1
        if instance not in self.instances:
            if self.instances:
                self.table.insertColumn(1 + len(self.instances))
            self.instances.append(instance)
            self._set_headers()
            self._sized = False
        return 1 + self.instances.index(instance)

    def show_snapshots(self, snapshots: Iterable[HousekeepingSnapshot]) -> None:
        """Show the newest packet (per agent) of this kind, with limit colours."""
        newest = None
        field = self.instance_field
        by_instance = sorted(snapshots, key=lambda s: "" if field is None else str(s.fields.get(field, "")))
        for snap in by_instance:
            instance = str(snap.fields.get(self.instance_field, "")) if self.instance_field else ""
            column = self._column(instance)
            newest = snap if newest is None or snap.recorded_at > newest.recorded_at else newest
            for r, fd in enumerate(self.rows):
                value = snap.fields.get(fd.name)
                colour = fd.limits.classify(value) if fd.limits is not None else None
                item = QtWidgets.QTableWidgetItem(value_text(fd, value))
                item.setData(QtGui.Qt.ItemDataRole.UserRole, colour)
                if colour:
                    item.setBackground(brush(LIMIT_COLOURS[colour]))
                self.table.setItem(r, column, item)
        if newest is not None:
            self.header.setText(
                f"{self.pdef.name} (APID {self.pdef.apid:#05x}): {self.pdef.description}  "
                f"packet {newest.packet_id} of {clock_text(newest.time)}"
            )
        if not self._sized:
            self.table.resizeColumnsToContents()
            self._sized = True

    def cell(self, field: str, instance: str = "") -> QtWidgets.QTableWidgetItem | None:
        """The value cell of ``field`` (for ``instance`` on a per-agent page)."""
        row = next((r for r, fd in enumerate(self.rows) if fd.name == field), None)
        if row is None:
            return None
        column = 1 if not self.instance_field else 1 + self.instances.index(instance)
        return self.table.item(row, column)


class HousekeepingPages(QtWidgets.QTabWidget):
    """One :class:`HousekeepingPage` per housekeeping kind."""

    def __init__(
        self,
        defs: Definitions,
        kinds: Iterable[str],
        instance_field: Mapping[str, str],
        exporter: Callable[[str, Path], int] | None = None,
    ) -> None:
        super().__init__()
        self.setObjectName("housekeeping")
        self.exporter = exporter
        if exporter is not None:
            button = QtWidgets.QPushButton("Export CSV…")
            button.setObjectName("export_csv")
            button.setToolTip("write every packet of this page's kind, up to now, to a CSV file")
            button.clicked.connect(self._export_dialog)
            self.setCornerWidget(button)
        self.pages: dict[str, HousekeepingPage] = {}
        for kind in kinds:
            page = HousekeepingPage(defs.packet(kind), instance_field.get(kind))
            self.pages[kind] = page
            self.addTab(page, kind)
        self._dirty: set[str] = set()
        self._housekeeping: Mapping[tuple[str, str], HousekeepingSnapshot] = {}
        self.currentChanged.connect(lambda _: self._draw(self.currentWidget()))

    def show_housekeeping(
        self,
        housekeeping: Mapping[tuple[str, str], HousekeepingSnapshot],
        kinds: Iterable[str],
    ) -> None:
        """Redraw the visible page if its kind changed; the others when they are shown."""
        self._housekeeping = housekeeping
        for kind in kinds:  # tab colours follow every page, shown or not
            page = self.pages.get(kind)
            if page is None:
                continue
            self._dirty.add(kind)
            worst = _worst(page, housekeeping)
            if worst != page.worst:
                page.worst = worst
                self.tabBar().setTabTextColor(self.indexOf(page), QtGui.QColor(_TAB_TEXT[worst]))
        self._draw(self.currentWidget())

    def current_kind(self) -> str:
        page = self.currentWidget()
        return page.pdef.name if isinstance(page, HousekeepingPage) else ""

    def _export_dialog(self) -> None:
        kind = self.current_kind()
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, f"Export {kind}", f"{kind}.csv", "CSV (*.csv)")
        if path:
            self.export(kind, Path(path))

    def export(self, kind: str, path: Path) -> str:
        """Export ``kind`` to ``path`` and return the sentence shown in the corner button's tooltip."""
        assert self.exporter is not None
        try:
            rows = self.exporter(kind, path)
        except (OSError, ValueError, RuntimeError) as exc:  # ArchiveError is a RuntimeError
            text = f"export of {kind} failed: {exc}"
        else:
            text = f"wrote {rows} {kind} packet(s) to {path}"
        corner = self.cornerWidget()
        if corner is not None:
            corner.setToolTip(text)
        return text

    def _draw(self, page: QtWidgets.QWidget | None) -> None:
        if not isinstance(page, HousekeepingPage) or page.pdef.name not in self._dirty:
            return
        self._dirty.discard(page.pdef.name)
        page.show_snapshots([s for (k, _), s in self._housekeeping.items() if k == page.pdef.name])


def _worst(
    page: HousekeepingPage, housekeeping: Mapping[tuple[str, str], HousekeepingSnapshot]
) -> str | None:
    rank = 0
    for (kind, _), snap in housekeeping.items():
        if kind != page.pdef.name:
            continue
        for fd in page.rows:
            if fd.limits is not None:
                colour = fd.limits.classify(snap.fields.get(fd.name))
                rank = max(rank, {None: 0, "yellow": 1, "red": 2}[colour])
    return {0: None, 1: "yellow", 2: "red"}[rank]


__all__ = ["HousekeepingPage", "HousekeepingPages"]
