"""Tree viewer: text for logs and a PNG image."""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from tlt_common.bt import status_codec as sc
from tlt_common.bt.nodes import BlackboardCondition
from tlt_common.bt.viewer import render_png, render_text


def tree():
    py_trees.blackboard.Blackboard.set("/started", True)
    build = py_trees.composites.Sequence(
        "Build Tower",
        memory=True,
        children=[py_trees.behaviours.Success("Raise Payload"), py_trees.behaviours.Running("Lower Lifter")],
    )
    return py_trees.composites.Selector(
        "CRS", memory=False, children=[BlackboardCondition("started?", "started", lambda v: not v), build]
    )


def test_text_rendering_marks_status_and_type():
    root = tree()
    root.tick_once()
    text = render_text(root).splitlines()
    assert text[0] == "* [?] CRS"
    assert text[1].startswith("    ✘ (started?)")
    assert text[2] == "    * [-->] Build Tower"
    assert text[3].startswith("        ✔ Raise Payload")
    assert text[4].startswith("        * Lower Lifter")


def test_text_rendering_from_decoded_statuses():
    robot = tree()
    robot.tick_once()
    ground = tree()
    shape = sc.TreeShape.of(ground)
    decoded = sc.decode(sc.encode(sc.TreeShape.of(robot), agent="crs", tick_count=1), shape)
    text = render_text(ground, statuses=decoded.as_dict())
    assert text == render_text(robot, show_feedback=False)


def test_collapse_untouched_branches():
    root = tree()
    assert render_text(root, collapse_invalid=True).splitlines()[1] == "    ... 4 nodes not ticked"
    py_trees.blackboard.Blackboard.set("/started", False)
    root.tick_once()  # the condition succeeds: Build Tower is never ticked
    text = render_text(root, collapse_invalid=True)
    assert "- [-->] Build Tower\n        ... 2 nodes not ticked" in text
    assert "Raise Payload" not in text


def test_png_is_written(tmp_path):
    root = tree()
    root.tick_once()
    path = render_png(root, tmp_path / "crs.png", title="CRS")
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 2000
    statuses = {n: Status.FAILURE for n in ("CRS", "CRS/Build Tower")}
    other = render_png(root, tmp_path / "failed.png", statuses=statuses)
    assert other.read_bytes() != data


def test_ground_renders_from_a_definition(tmp_path):
    from tlt_common.bt.viewer import placeholder_tree

    robot = tree()
    robot.tick_once()
    robot_shape = sc.TreeShape.of(robot)
    ground_shape = sc.TreeShape.from_definition(robot_shape.definition())
    decoded = sc.decode(sc.encode(robot_shape, agent="crs", tick_count=9), ground_shape)
    shown = placeholder_tree(ground_shape)
    assert render_text(shown, statuses=decoded.as_dict()) == render_text(robot, show_feedback=False)
    assert render_png(shown, tmp_path / "ground.png", statuses=decoded.as_dict()).stat().st_size > 2000
