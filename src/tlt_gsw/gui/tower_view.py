"""Tower view: which bays and members are placed, riveted and inspected.

Reads the newest ``hk_tower`` packet (one 2-bit state per member in mission order, see
:mod:`tlt_gsw.gui.tower_layout`) and ``hk_mission`` (run state, bays built, current bay, members
placed and riveted, current step, fault). Draws the tower in an oblique view from the mission's
joint coordinates (each member a line, a cross frame a square, a foundation rivet a dot, coloured
by state), and lists the members bay by bay in a table. Without a matching mission file the
standard layout of the reported bay count is used, else the members are only numbered.
"""

from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

from tlt_common.mission.schema import Mission
from tlt_gsw.gui.archive_records import HousekeepingSnapshot
from tlt_gsw.gui.style import brush
from tlt_gsw.gui.tower_layout import (
    INSPECTED,
    NOT_PLACED,
    PLACED,
    RIVETED,
    STATE_LABELS,
    TowerLayout,
    TowerStateError,
    choose_layout,
    unpack_member_states,
)

STATE_COLOURS = {NOT_PLACED: "#c8c8c8", PLACED: "#f0a030", RIVETED: "#3c9a3c", INSPECTED: "#1f5fa8"}


def _project(x: float, y: float, z: float) -> tuple[float, float]:
    # Oblique view: x to the right, depth (y) up and to the right, z up (bays hang below z = 0).
    return x + 0.55 * y, -z - 0.35 * y


class TowerDrawing(QtWidgets.QWidget):
    """Paints the members of a layout in their state colours."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.layout_: TowerLayout | None = None
        self.states: list[int] = []
        self.current_bay = 0
        self.setMinimumSize(260, 260)

    def show_states(self, layout: TowerLayout, states: list[int], current_bay: int) -> None:
        self.layout_, self.states, self.current_bay = layout, states, current_bay
        self.update()

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:
        painter = QtGui.QPainter(self)
        painter.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing)
        painter.fillRect(self.rect(), QtGui.QColor("#ffffff"))
        layout = self.layout_
        if layout is None or not layout.members:
            painter.drawText(self.rect(), QtCore.Qt.AlignmentFlag.AlignCenter, "no tower model received yet")
            return
        points = [_project(*p) for m in layout.members for p in m.points]
        if not points:
            self._paint_numbered(painter, layout)
            return
        us, vs = [p[0] for p in points], [p[1] for p in points]
        vs.append(min(vs) - 0.05)
        margin, legend = 16, 22
        span_u, span_v = max(us) - min(us) or 1.0, max(vs) - min(vs) or 1.0
        labels = 110  # room right of the tower for the bay names
        scale = min(
            (self.width() - 2 * margin - labels) / span_u, (self.height() - 2 * margin - legend) / span_v
        )
        u0, v0 = min(us), min(vs)

        def at(p: tuple[float, float, float]) -> QtCore.QPointF:
            u, v = _project(*p)
            return QtCore.QPointF(margin + (u - u0) * scale, margin + (v - v0) * scale)

        for member in layout.members:
            state = self.states[member.index] if member.index < len(self.states) else NOT_PLACED
            colour = QtGui.QColor(STATE_COLOURS[state])
            pen = QtGui.QPen(colour, 2.5 if state != NOT_PLACED else 1.2)
            if state == NOT_PLACED:
                pen.setStyle(QtCore.Qt.PenStyle.DashLine)
            painter.setPen(pen)
            corners = [at(p) for p in member.points]
            if member.kind == "foundation_rivet" and corners:
                painter.setBrush(QtGui.QBrush(colour))
                painter.drawEllipse(corners[0], 4.5, 4.5)
                painter.setBrush(QtCore.Qt.BrushStyle.NoBrush)
            elif len(corners) > 2:
                painter.drawPolygon(QtGui.QPolygonF(corners))
            elif len(corners) == 2:
                painter.drawLine(corners[0], corners[1])
        painter.setPen(QtGui.QColor("#000000"))
        for member in layout.members:  # each bay is named beside its bottom cross frame
            if member.kind != "cross_frame" or not member.points:
                continue
            corners = [at(p) for p in member.points]
            anchor = QtCore.QPointF(
                max(c.x() for c in corners) + 8, sum(c.y() for c in corners) / len(corners)
            )
            font = painter.font()
            font.setBold(member.bay == self.current_bay)
            painter.setFont(font)
            current = "  ← building" if member.bay == self.current_bay else ""
            painter.drawText(anchor, f"bay {member.bay}{current}")
        font = painter.font()
        font.setBold(False)
        painter.setFont(font)
        x = margin
        y = self.height() - 8
        for state, label in STATE_LABELS.items():
            painter.setPen(QtGui.QPen(QtGui.QColor(STATE_COLOURS[state]), 6))
            painter.drawLine(QtCore.QPointF(x, y - 4), QtCore.QPointF(x + 14, y - 4))
            painter.setPen(QtGui.QColor("#000000"))
            painter.drawText(QtCore.QPointF(x + 18, y), label)
            x += 26 + painter.fontMetrics().horizontalAdvance(label)

    def _paint_numbered(self, painter: QtGui.QPainter, layout: TowerLayout) -> None:
        side, gap, per_row = 18, 4, max(1, (self.width() - 20) // 22)
        for member in layout.members:
            state = self.states[member.index] if member.index < len(self.states) else NOT_PLACED
            r, c = divmod(member.index, per_row)
            painter.fillRect(
                10 + c * (side + gap), 10 + r * (side + gap), side, side, QtGui.QColor(STATE_COLOURS[state])
            )


class TowerView(QtWidgets.QWidget):
    """Summary line, drawing and member table; :meth:`show_tower` updates them."""

    def __init__(self, mission: Mission | None, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.mission = mission
        self.layout_: TowerLayout | None = None
        self.states: list[int] = []
        outer = QtWidgets.QVBoxLayout(self)
        self.summary = QtWidgets.QLabel("no mission progress received yet")
        self.summary.setObjectName("tower_summary")
        self.summary.setWordWrap(True)
        outer.addWidget(self.summary)
        split = QtWidgets.QSplitter()
        self.drawing = TowerDrawing()
        self.drawing.setObjectName("tower_drawing")
        self.table = QtWidgets.QTableWidget(0, 0)
        self.table.setObjectName("tower_table")
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        split.addWidget(self.drawing)
        split.addWidget(self.table)
        split.setSizes([420, 520])
        outer.addWidget(split, 1)

    def show_tower(self, tower: HousekeepingSnapshot | None, mission: HousekeepingSnapshot | None) -> None:
        progress = mission.fields if mission is not None else {}
        if progress:
            text = (
                f"Run state: {progress.get('run_state')}   Bays built: {progress.get('bays_built')} of "
                f"{progress.get('bays_total')} (current bay {progress.get('current_bay')})   Members placed: "
                f"{progress.get('members_placed')}, riveted: {progress.get('members_riveted')} of "
                f"{progress.get('members_total')}\nStep: {progress.get('current_step') or '-'}"
            )
            if progress.get("fault"):
                text += f"   FAULT: {progress['fault']}"
            self.summary.setText(text)
            self.summary.setStyleSheet("color: #a01010; font-weight: bold;" if progress.get("fault") else "")
        if tower is None:
            return
        count = int(tower.fields.get("member_count") or 0)
        try:
            states = unpack_member_states(bytes(tower.fields.get("member_states") or b""), count)
        except TowerStateError as exc:
            self.summary.setText(f"{self.summary.text()}\nhk_tower unreadable: {exc}")
            return
        bays = progress.get("bays_total")
        if (
            self.layout_ is None
            or len(self.layout_.members) != count
            or (self.layout_.source.startswith("standard") and bays and self.layout_.bay_count != bays)
        ):
            self.layout_ = choose_layout(count, bays, self.mission)
            self._build_table(self.layout_)
        self.states = states
        self.drawing.show_states(self.layout_, states, int(progress.get("current_bay") or 0))
        self._fill_table(states)

    # -- table ------------------------------------------------------------------------------
    def _build_table(self, layout: TowerLayout) -> None:
        self._cells: dict[int, tuple[int, int]] = {}
        if layout.bay_count == 0:
            per_row = 10
            self.table.setColumnCount(per_row)
            self.table.setRowCount((len(layout.members) + per_row - 1) // per_row)
            self.table.setHorizontalHeaderLabels([str(i + 1) for i in range(per_row)])
            for m in layout.members:
                self._cells[m.index] = divmod(m.index, per_row)
            return
        columns: list[str] = []
        for m in layout.members:
            if m.kind != "foundation_rivet":
                slot = m.id.split("/", 1)[1] if "/" in m.id else m.id
                if slot not in columns:
                    columns.append(slot)
        rows = [f"bay {n}" for n in range(1, layout.bay_count + 1)]
        foundation = [m for m in layout.members if m.kind == "foundation_rivet"]
        if foundation:
            rows.append("foundation")
        self.table.setColumnCount(len(columns))
        self.table.setRowCount(len(rows))
        self.table.setHorizontalHeaderLabels([c.replace("/", " ") for c in columns])
        self.table.setVerticalHeaderLabels(rows)
        for m in layout.members:
            if m.kind == "foundation_rivet":
                self._cells[m.index] = (len(rows) - 1, foundation.index(m))
            else:
                slot = m.id.split("/", 1)[1] if "/" in m.id else m.id
                self._cells[m.index] = (m.bay - 1, columns.index(slot))
        self.table.setRowCount(len(rows))

    def _fill_table(self, states: list[int]) -> None:
        assert self.layout_ is not None
        for m in self.layout_.members:
            row, column = self._cells[m.index]
            state = states[m.index]
            text = STATE_LABELS[state] if self.layout_.bay_count else f"{m.index + 1}: {STATE_LABELS[state]}"
            if m.kind == "foundation_rivet":
                text = f"{m.position}: {STATE_LABELS[state]}"
            item = QtWidgets.QTableWidgetItem(text)
            item.setToolTip(m.id)
            item.setBackground(brush(STATE_COLOURS[state]))
            if state in (RIVETED, INSPECTED):
                item.setForeground(brush("#ffffff"))
            self.table.setItem(row, column, item)
        self.table.resizeColumnsToContents()

    def member_state(self, member_id: str) -> str | None:
        """The state label shown for ``member_id`` (tests)."""
        if self.layout_ is None:
            return None
        for m in self.layout_.members:
            if m.id == member_id:
                return STATE_LABELS[self.states[m.index]]
        return None


__all__ = ["STATE_COLOURS", "TowerDrawing", "TowerView"]
