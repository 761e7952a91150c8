"""Text and PNG renderings of a behaviour tree with its statuses (logs, README, GSW).

Symbols follow Table 3 of the paper: a Sequence is drawn "-->", a Fallback "?", a Parallel "=>";
an Action is a rectangle with its name, a Condition an ellipse with its name. Colours give the
status: green SUCCESS, red FAILURE, amber RUNNING, grey INVALID (not ticked).
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from pathlib import Path

import py_trees
from py_trees.common import Status

from tlt_common.bt.nodes import Action, Condition, node_kind
from tlt_common.bt.status_codec import TreeShape

SYMBOLS = {"sequence": "-->", "fallback": "?", "parallel": "=>", "decorator": "◇"}
STATUS_MARK = {Status.SUCCESS: "✔", Status.FAILURE: "✘", Status.RUNNING: "*", Status.INVALID: "-"}
STATUS_COLOUR = {
    Status.SUCCESS: "#7bc96f",
    Status.FAILURE: "#e8736c",
    Status.RUNNING: "#f5c04a",
    Status.INVALID: "#d9d9d9",
}


class _ShownCondition(Condition):
    """Stands for a condition of a tree known only by its shape; it is drawn, never ticked."""

    def evaluate(self) -> bool:
        return False


class _ShownAction(Action):
    """Stands for an action of a tree known only by its shape; it is drawn, never ticked."""

    def update(self) -> Status:
        return Status.FAILURE


class _ShownDecorator(py_trees.decorators.Decorator):
    def update(self) -> Status:
        return self.decorated.status


def placeholder_tree(shape: TreeShape) -> py_trees.behaviour.Behaviour:
    """A tree of the same names, kinds and structure as ``shape`` (e.g. one rebuilt on the ground
    from a definition), for :func:`render_text` and :func:`render_png` with decoded statuses."""
    built: list[py_trees.behaviour.Behaviour] = []
    # Children come after their parent in pre-order; build bottom-up so decorators get their child.
    children: dict[int, list[py_trees.behaviour.Behaviour]] = {}
    for node in reversed(shape.nodes):
        kids = list(reversed(children.pop(node.index, [])))
        b: py_trees.behaviour.Behaviour
        if node.kind == "sequence":
            b = py_trees.composites.Sequence(node.name, memory=False, children=kids)
        elif node.kind == "fallback":
            b = py_trees.composites.Selector(node.name, memory=False, children=kids)
        elif node.kind == "parallel":
            b = py_trees.composites.Parallel(
                node.name, policy=py_trees.common.ParallelPolicy.SuccessOnAll(), children=kids
            )
        elif node.kind == "decorator" and len(kids) == 1:
            b = _ShownDecorator(name=node.name, child=kids[0])
        elif node.kind == "condition":
            b = _ShownCondition(node.name)
        else:
            b = _ShownAction(node.name)
        children.setdefault(node.parent, []).append(b)
        built.append(b)
    return built[-1]


def _label(behaviour: py_trees.behaviour.Behaviour) -> str:
    kind = node_kind(behaviour)
    if kind in SYMBOLS:
        return f"[{SYMBOLS[kind]}] {behaviour.name}"
    if kind == "condition":
        return f"({behaviour.name})"
    return behaviour.name


def render_text(
    root: py_trees.behaviour.Behaviour,
    *,
    statuses: Mapping[str, Status] | None = None,
    show_feedback: bool = True,
    collapse_invalid: bool = False,
) -> str:
    """One line per node, indented by depth: status mark, Table 3 symbol, name, feedback.

    ``statuses`` (path -> status, as decoded by the status codec) overrides the behaviours' own
    statuses, so the ground can render a tree it only knows by definition. ``collapse_invalid``
    hides the children of composites that were not ticked, to keep logs of big trees short.
    """
    lines: list[str] = []

    def visit(node: py_trees.behaviour.Behaviour, depth: int, path: str) -> None:
        path = f"{path}/{node.name}" if path else node.name
        status = statuses.get(path, node.status) if statuses is not None else node.status
        line = f"{'    ' * depth}{STATUS_MARK[status]} {_label(node)}"
        if show_feedback and node.feedback_message and statuses is None:
            line += f" -- {node.feedback_message}"
        lines.append(line)
        if collapse_invalid and status is Status.INVALID and node.children:
            lines.append(f"{'    ' * (depth + 1)}... {sum(1 for _ in node.iterate()) - 1} nodes not ticked")
            return
        for child in node.children:
            visit(child, depth + 1, path)

    visit(root, 0, "")
    return "\n".join(lines)


def _wrap(name: str, width: int = 20) -> str:
    """Break a long node name over lines at spaces and after '/', so it fits its box."""
    tokens = name.replace("/", "/\0").replace(" ", " \0").split("\0")
    lines, line = [], ""
    for token in tokens:
        if line and len(line) + len(token) > width:
            lines.append(line.rstrip())
            line = ""
        line += token
    lines.append(line.rstrip())
    return "\n".join(lines)


def _layout(root: py_trees.behaviour.Behaviour) -> dict[int, tuple[float, int]]:
    """x (leaves spaced one apart, parents centred over their children) and depth per node id."""
    positions: dict[int, tuple[float, int]] = {}
    next_leaf = [0.0]

    def place(node: py_trees.behaviour.Behaviour, depth: int) -> float:
        if not node.children:
            x = next_leaf[0]
            next_leaf[0] += 1.0
        else:
            xs = [place(child, depth + 1) for child in node.children]
            x = (xs[0] + xs[-1]) / 2
        positions[id(node)] = (x, depth)
        return x

    place(root, 0)
    return positions


def render_png(
    root: py_trees.behaviour.Behaviour,
    path: str | Path,
    *,
    statuses: Mapping[str, Status] | None = None,
    title: str | None = None,
    dpi: int = 100,
) -> Path:
    """Draw the tree to a PNG file and return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(render_png_bytes(root, statuses=statuses, title=title, dpi=dpi))
    return path


def render_png_bytes(
    root: py_trees.behaviour.Behaviour,
    *,
    statuses: Mapping[str, Status] | None = None,
    title: str | None = None,
    dpi: int = 100,
) -> bytes:
    """Draw the tree as PNG bytes (for a GUI to show or a log to attach)."""
    # A bare Figure on the Agg canvas: no pyplot state, so it is safe inside the Qt GSW and threads.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Ellipse, FancyBboxPatch, Patch

    positions = _layout(root)
    width = max(x for x, _ in positions.values()) + 1
    depth = max(d for _, d in positions.values()) + 1
    x_step, y_step = 1.9, 1.5
    fig_w = max(4.0, width * x_step * 0.75)
    fig_h = max(2.5, depth * y_step * 0.75)
    fig = Figure(figsize=(fig_w, fig_h))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.set_xlim(-1.0, width * x_step)
    ax.set_ylim(-depth * y_step, 0.9)
    ax.set_axis_off()

    def centre(node: py_trees.behaviour.Behaviour) -> tuple[float, float]:
        x, d = positions[id(node)]
        return x * x_step, -d * y_step

    def draw(node: py_trees.behaviour.Behaviour, path: str) -> None:
        path = f"{path}/{node.name}" if path else node.name
        status = statuses.get(path, node.status) if statuses is not None else node.status
        cx, cy = centre(node)
        for child in node.children:
            kx, ky = centre(child)
            ax.plot([cx, kx], [cy - 0.3, ky + 0.35], color="#555555", linewidth=0.8, zorder=1)
        colour = STATUS_COLOUR[status]
        kind = node_kind(node)
        if kind in SYMBOLS:
            ax.add_patch(
                FancyBboxPatch(
                    (cx - 0.35, cy - 0.3), 0.7, 0.6, boxstyle="square,pad=0", fc=colour, ec="black", zorder=2
                )
            )
            ax.text(cx, cy, SYMBOLS[kind], ha="center", va="center", fontsize=10, weight="bold", zorder=3)
            ax.text(cx, cy + 0.32, _wrap(node.name, 28), ha="center", va="bottom", fontsize=6, zorder=3)
        elif kind == "condition":
            ax.add_patch(Ellipse((cx, cy), 1.8, 0.75, fc=colour, ec="black", zorder=2))
            ax.text(cx, cy, _wrap(node.name), ha="center", va="center", fontsize=6, zorder=3)
        else:
            ax.add_patch(
                FancyBboxPatch(
                    (cx - 0.85, cy - 0.35),
                    1.7,
                    0.7,
                    boxstyle="round,pad=0.02",
                    fc=colour,
                    ec="black",
                    zorder=2,
                )
            )
            ax.text(cx, cy, _wrap(node.name), ha="center", va="center", fontsize=6, zorder=3)
        for child in node.children:
            draw(child, path)

    draw(root, "")
    legend = [Patch(fc=c, ec="black", label=s.name) for s, c in STATUS_COLOUR.items()]
    ax.legend(handles=legend, loc="lower left", fontsize=6, frameon=False, ncol=4)
    if title:
        ax.set_title(title)
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=dpi, bbox_inches="tight")
    return out.getvalue()


__all__ = ["placeholder_tree", "render_png", "render_png_bytes", "render_text"]
