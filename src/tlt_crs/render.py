"""Text and PNG renderings of the CRS tree of a mission, for the documentation and operators.

``python -m tlt_crs.render [--mission missions/one_bay.yaml] [--out docs/images] [--depth 6]``
prints the whole tree as text and writes ``crs-tree.png`` (the tree down to ``--depth``, deeper
branches folded into one box each) and one PNG per figure-sized subtree of bay 1:
``crs-raise-payload.png`` (Fig. 18), ``crs-far-vertical.png`` (Fig. 23), ``crs-test-bay.png``
(Fig. 26). The tree is built as ``tlt-crs`` builds it, on a throw-away rclpy node.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import py_trees
from py_trees.common import Status

from tlt_common.bt.nodes import Action, Condition, node_kind
from tlt_common.bt.viewer import render_png, render_text
from tlt_crs.config import REPO_CONFIG, load_config


class _Shown(Action):
    def update(self) -> Status:
        return Status.FAILURE


class _ShownCondition(Condition):
    def evaluate(self) -> bool:
        return False


def folded(node: py_trees.behaviour.Behaviour, depth: int) -> py_trees.behaviour.Behaviour:
    """A drawable copy of ``node`` whose branches below ``depth`` are one box each ("name ...")."""
    kind = node_kind(node)
    if node.children and depth <= 0:
        count = sum(1 for _ in node.iterate()) - 1
        return _Shown(f"{node.name} (+{count})")
    children = [folded(c, depth - 1) for c in node.children]
    if isinstance(node, py_trees.composites.Selector):  # node_kind's "fallback"
        return py_trees.composites.Selector(node.name, memory=node.memory, children=children)
    if isinstance(node, py_trees.composites.Sequence):
        return py_trees.composites.Sequence(node.name, memory=node.memory, children=children)
    if kind == "decorator":
        return py_trees.decorators.PassThrough(node.name, children[0])
    return _ShownCondition(node.name) if kind == "condition" else _Shown(node.name)


def find(root: py_trees.behaviour.Behaviour, name: str) -> py_trees.behaviour.Behaviour:
    return next(n for n in root.iterate() if n.name == name)


def main(argv: list[str] | None = None) -> int:
    import rclpy

    from tlt_crs.node import build_node

    parser = argparse.ArgumentParser(description="Render the CRS tree of a mission.")
    parser.add_argument("--mission", type=Path, default=Path("missions/one_bay.yaml"))
    parser.add_argument("--out", type=Path, default=Path("docs/images"))
    parser.add_argument("--depth", type=int, default=6)
    args = parser.parse_args(argv)
    rclpy.init()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            config = load_config(REPO_CONFIG, mission=args.mission, state_file=Path(tmp) / "tower.json")
            node = build_node(config, node_name="crs_render")
            root = node.root
            print(render_text(root, show_feedback=False))
            render_png(folded(root, args.depth), args.out / "crs-tree.png", title="CRS tree (Fig. 13)")
            for name, file, title in (
                ("Raise Payload", "crs-raise-payload.png", "Raise Payload (Fig. 18)"),
                ("Add Far Vertical x0_y1", "crs-far-vertical.png", "Add Far Vertical x0_y1 (Fig. 23)"),
                ("Test Bay 1", "crs-test-bay.png", "Test Bay (Fig. 26)"),
            ):
                render_png(folded(find(root, name), 4), args.out / file, title=title)
            node.destroy_node()
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
