"""Behaviour-tree view: each agent's tree with node statuses in colour, decoded from status bytes.

The agents send ``tree_status`` packets (2 bits per node in pre-order, a shape hash, a tick count;
docs/behaviour-trees.md). :class:`ArchiveModel` reassembles and decodes them with the agent's tree
shape definition; this view draws the shape as a tree widget (Table 3 symbols: ``-->`` Sequence,
``?`` Fallback, ``(name)`` Condition) and colours each node: green SUCCESS, red FAILURE, amber
RUNNING, grey not ticked this tick. With "follow" on, branches that were not ticked are folded so
the running path stays in view. An agent without a definition (or whose tree changed shape) is
listed with its tick, shape hash, node count, status counts and the reason.
"""

from __future__ import annotations

from py_trees.common import Status
from PySide6 import QtWidgets

from tlt_common.bt.status_codec import TreeShape
from tlt_gsw.gui.agent_trees import status_counts
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.style import STATUS_NAMES, brush, status_colour

_SYMBOL = {"sequence": "[-->]", "fallback": "[?]", "parallel": "[=>]", "decorator": "[◇]"}


def node_label(kind: str, name: str) -> str:
    if kind == "condition":
        return f"({name})"
    symbol = _SYMBOL.get(kind)
    return f"{symbol} {name}" if symbol else name


class TreeStatusView(QtWidgets.QWidget):
    """Agent chooser, summary line and the tree; :meth:`show_trees` updates from the model."""

    def __init__(self, model: ArchiveModel, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        layout = QtWidgets.QVBoxLayout(self)
        row = QtWidgets.QHBoxLayout()
        self.agent = QtWidgets.QComboBox()
        self.agent.setObjectName("tree_agent")
        self.agent.currentTextChanged.connect(lambda _: self._rebuild())
        self.follow = QtWidgets.QCheckBox("Follow the ticked branches")
        self.follow.setChecked(True)
        self.follow.toggled.connect(lambda _: self._rebuild())
        row.addWidget(QtWidgets.QLabel("Agent"))
        row.addWidget(self.agent)
        row.addWidget(self.follow)
        row.addStretch(1)
        layout.addLayout(row)
        self.summary = QtWidgets.QLabel("no tree status received yet")
        self.summary.setObjectName("tree_summary")
        self.summary.setWordWrap(True)
        layout.addWidget(self.summary)
        self.tree = QtWidgets.QTreeWidget()
        self.tree.setObjectName("tree_view")
        self.tree.setHeaderLabels(["Node", "Type", "Status"])
        self.tree.setColumnWidth(0, 380)
        layout.addWidget(self.tree, 1)
        self._items: list[QtWidgets.QTreeWidgetItem] = []
        self._shown: tuple[str, int] | None = None  # (agent, shape hash) the items were built for
        self._statuses: list[Status] = []

    def show_trees(self, agents: set[str] | None = None) -> None:
        known = [self.agent.itemText(i) for i in range(self.agent.count())]
        for agent in sorted(self.model.trees):
            if agent not in known:
                self.agent.addItem(agent)
        current = self.agent.currentText()
        if agents is None or current in agents:
            self._update(current)

    def _rebuild(self) -> None:
        self._shown = None
        self._update(self.agent.currentText())

    def _update(self, agent: str) -> None:
        state = self.model.trees.get(agent)
        if state is None:
            self.tree.clear()
            self._items, self._shown = [], None
            self.summary.setText("no tree status received yet")
            return
        counts = status_counts(state)
        shown = ", ".join(f"{STATUS_NAMES[s]} {counts.get(s, 0)}" for s in STATUS_NAMES)
        text = f"{agent}: tick {state.tick}, shape {state.shape_hash:08x}, {state.node_count} nodes ({shown})"
        if state.error:
            text += f"\n{state.error}"
        self.summary.setText(text)
        self.summary.setStyleSheet("color: #a01010;" if state.error else "")
        shape = self.model.shapes.get(agent)
        if state.decoded is None or shape is None:
            if self._shown is not None:
                self.tree.clear()
                self._items, self._shown = [], None
            return
        if self._shown != (agent, shape.hash):
            self._build(shape)
            self._shown = (agent, shape.hash)
        statuses = [s for _, s in state.decoded.nodes]
        follow = self.follow.isChecked()
        for i, (item, status) in enumerate(zip(self._items, statuses, strict=True)):
            if i < len(self._statuses) and self._statuses[i] is status:
                continue
            item.setText(2, STATUS_NAMES[status])
            colour = brush(status_colour(status))
            for column in range(3):
                item.setBackground(column, colour)
            if follow and item.childCount():
                item.setExpanded(status is not Status.INVALID)
        self._statuses = statuses

    def _build(self, shape: TreeShape) -> None:
        self.tree.clear()
        self._items = []
        self._statuses = []
        for node in shape.nodes:
            parent = self._items[node.parent] if node.parent >= 0 else self.tree.invisibleRootItem()
            item = QtWidgets.QTreeWidgetItem(parent, [node_label(node.kind, node.name), node.kind, ""])
            item.setToolTip(0, node.path)
            self._items.append(item)
        if not self.follow.isChecked():
            self.tree.expandAll()

    def node_rows(self) -> list[tuple[str, str]]:
        """(path, status text) of every node shown, in pre-order (tests)."""
        return [(item.toolTip(0), item.text(2)) for item in self._items]


__all__ = ["TreeStatusView", "node_label"]
