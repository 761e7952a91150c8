"""Pictures of the ARS tree for docs/ars.md, drawn with the shared viewer (tlt_common.bt.viewer).

The real tree is built (for ``ars_x`` and its mission, in a private ROS context: the behaviours
create their clients) and copied into plain display nodes of the same kinds, so the pictures
always show the tree the ARS runs. Each named motion ("Approach Dispenser": plan, then execute)
is drawn as one action; ``depth`` cuts subtrees below it to one node, for the overview.

``python -m tlt_ars.tree_figure --out docs/images`` writes ``ars-tree.png`` (Fig. 14 with the Add
Member branch installed, subtrees folded), and ``ars-add-member.png``, ``ars-add-cross-frame.png``,
``ars-affix-member.png``, ``ars-foundation-rivet.png`` (one branch each, motions folded).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import py_trees
from py_trees.common import Status

from tlt_common.bt.nodes import Action, Condition, node_kind
from tlt_common.bt.viewer import render_png


class _ShownAction(Action):
    def update(self) -> Status:
        return Status.SUCCESS


class _ShownDecorator(py_trees.decorators.Decorator):
    def update(self) -> Status:
        return self.decorated.status


class _ShownCondition(Condition):
    def evaluate(self) -> bool:
        return True


def display_copy(
    node: py_trees.behaviour.Behaviour, depth: int | None = None
) -> py_trees.behaviour.Behaviour:
    """A copy of ``node`` made of display nodes: motions folded to one action; below ``depth``
    levels every subtree folded to one action named after it."""
    kind = node_kind(node)
    if getattr(node, "replan_on_resume", False):
        return _ShownAction(f"{node.name} (plan + execute)")
    if kind == "condition":
        return _ShownCondition(node.name)
    if not node.children and kind not in ("sequence", "fallback"):
        return _ShownAction(node.name)
    if depth is not None and depth <= 0:
        return _ShownAction(f"{node.name} ...")
    below = None if depth is None else depth - 1
    if kind == "fallback":
        copy: py_trees.behaviour.Behaviour = py_trees.composites.Selector(node.name, memory=True)
    elif kind == "parallel":
        copy = py_trees.composites.Parallel(node.name, policy=py_trees.common.ParallelPolicy.SuccessOnAll())
    elif kind == "decorator":
        return _ShownDecorator(name=node.name, child=display_copy(node.children[0], below))
    else:
        copy = py_trees.composites.Sequence(node.name, memory=True)
    copy.add_children([display_copy(child, below) for child in node.children])
    return copy


def render_all(out: Path) -> list[Path]:
    """Build ars_x's tree and draw the pictures listed in the module docstring."""
    import rclpy

    from tlt_ars.config import default_config_path, load_ars_config
    from tlt_ars.node import ArsNode

    context = rclpy.Context()
    rclpy.init(context=context)
    node = ArsNode(load_ars_config(default_config_path("ars_x")), context=context, check_reach=False)
    written = []
    try:
        mission = node.ctx.mission
        examples = {
            "add_member": ("ars-add-member.png", "bay1/diagonal/face_x0", "Add Member (Fig. 32), a diagonal"),
            "add_cross_frame": ("ars-add-cross-frame.png", "bay1/cross_frame", "Add Cross Frame (Fig. 28)"),
            "affix_member": ("ars-affix-member.png", "bay1/vertical/x0_y0", "Affix Member (Fig. 39)"),
            "foundation_rivet": (
                "ars-foundation-rivet.png",
                "foundation/x0_y0",
                "Foundation Rivet (Fig. 38)",
            ),
        }
        for request, (name, member_id, title) in examples.items():
            branch = node.tree.builder.branch(request, mission.member(member_id))
            written.append(render_png(display_copy(branch), out / name, title=title, dpi=70))
        # The overview: Fig. 14 with the Add Member branch installed, its subtrees folded.
        node.tree.slot.add_child(
            node.tree.builder.branch("add_member", mission.member("bay1/vertical/x0_y0"))
        )
        written.append(
            render_png(
                display_copy(node.tree.root, depth=4), out / "ars-tree.png", title="ARS X (Fig. 14)", dpi=80
            )
        )
    finally:
        node.close()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return written


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="ars-tree-figure", description="draw the ARS behaviour tree to PNGs"
    )
    parser.add_argument("--out", type=Path, default=Path("docs/images"), help="folder for the PNGs")
    args = parser.parse_args(argv)
    for path in render_all(args.out):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
