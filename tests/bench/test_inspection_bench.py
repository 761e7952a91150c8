"""The inspection benchmark: its scenario makes every defect kind, its jittered presentation is a
fair view (a good strut passes, one missing a fitting fails), and its figures are counted right."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tlt_common.mission.schema import load_mission
from tlt_vision.node_config import load_config
from tlt_vision.part_inspection import PartInspector

ROOT = Path(__file__).resolve().parents[2]
MISSION = load_mission(ROOT / "missions" / "one_bay.yaml")


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("inspection")


def test_half_the_struts_are_defective_with_every_kind_and_bend(bench):
    pytest.importorskip("tlt_sim.model.scenario")
    struts = bench.struts(MISSION)
    assert len(struts) == 16  # 5 + 3 verticals, 4 + 4 diagonals
    scen = bench.scenario(MISSION, [3.0, 9.0])
    labels = [bench.defect_label(scen.defects.get(name)) for name, _ in struts]
    assert labels.count("good") == 8
    missing_a, missing_b = "missing_end_fitting a", "missing_end_fitting b"
    assert {missing_a, missing_b, "bent_tube 3 deg", "bent_tube 9 deg"} <= set(labels)
    assert labels[:6] == ["good", missing_a, "good", missing_b, "good", "bent_tube 3 deg"]


def test_jittered_presentations_of_a_good_and_a_defective_strut_are_decided_right(bench):
    scene_mod = pytest.importorskip("tlt_sim.model.scene")
    scen = bench.scenario(MISSION, [8.0])
    inspector = PartInspector(load_config(), MISSION)
    rng = np.random.default_rng(5)
    decided, joints = {}, bench.inspection_joints()
    with scene_mod.Scene(mission=MISSION, scenario=scen) as scene:
        for arm, name in (("ars_x", "vertical_dispenser_x/0"), ("ars_y", "vertical_dispenser_x/1")):
            frame = bench.present(scene, scene.part(name), arm, joints[arm], rng, bench.Jitter())
            detections = bench.detector("twin")(frame, bench.CAMERAS[arm])
            decided[name], _ = inspector.inspect(
                "bench/vertical", "vertical", detections, frame.depth, frame.intrinsics, frame.rgb
            )
    good, missing = decided["vertical_dispenser_x/0"], decided["vertical_dispenser_x/1"]
    assert good.passed, good.reasons
    assert not missing.passed, missing.reasons
    assert any(r.startswith("missing end fitting") for r in missing.reasons), missing.reasons


def test_the_shipped_mask_rcnn_passes_good_held_struts_and_catches_a_missing_fitting(bench):
    """As the vision node would run on Mask R-CNN (node.yaml's weights, scores and second look, the
    end effectors filtered out): a good vertical and a good diagonal in ARS X's closed jaws pass (the
    vertical's fitting beside the rivet gun scores under 0.5; the diagonal's tube mask takes in the
    jaws and the floor behind), and a vertical missing a fitting fails."""
    scene_mod = pytest.importorskip("tlt_sim.model.scene")
    from tlt_vision.self_filter import EeSelfFilter

    config = load_config()
    mission = load_mission(ROOT / "missions" / "two_bay.yaml")  # the bench's first presentation first
    scen = bench.scenario(mission, [8.0])
    labels = {name: bench.defect_label(scen.defects.get(name)) for name, _ in bench.struts(mission)}
    good_vertical, good_diagonal, missing = (
        next(n for n, label in labels.items() if label.startswith(want) and n.startswith(kind))
        for want, kind in (("good", "vertical"), ("good", "diagonal"), ("missing", "vertical"))
    )
    inspector = PartInspector(config, mission)
    ee_filter = EeSelfFilter.from_config(config.raw["ee_self_filter"])
    detect = bench.detector("mask_rcnn")
    rng = np.random.default_rng(1100)
    decided, joints = {}, bench.inspection_joints()
    with scene_mod.Scene(mission=mission, scenario=scen) as scene:
        for name in (good_vertical, good_diagonal, missing):
            part = scene.part(name)
            home = scene.body_pose(part.body)
            frame = bench.present(scene, part, "ars_x", joints["ars_x"], rng, bench.Jitter())
            depth = bench.without_own_ee(scene, frame, ee_filter)
            scene.place_part(name, *home)
            kind = name.split("_")[0]
            camera = bench.CAMERAS["ars_x"]
            decided[name], _ = inspector.inspect(
                f"bench/{kind}",
                kind,
                detect(frame, camera),
                depth,
                frame.intrinsics,
                frame.rgb,
                detect.closer(frame, camera),
            )
    assert decided[good_vertical].passed, decided[good_vertical].reasons
    assert decided[good_diagonal].passed, decided[good_diagonal].reasons
    reasons = decided[missing].reasons
    assert not decided[missing].passed and any(r.startswith("missing end fitting") for r in reasons), reasons


def test_figures_and_wrong_decisions(bench, capsys):
    P = bench.Presented
    results = [
        *(P(f"v/{i}", "ars_x", "good", True, ()) for i in range(49)),
        P("v/49", "ars_y", "good", False, ("missing end fitting: 1 of 2 found",)),  # rejected
        P("d/0", "ars_x", "missing_end_fitting a", False, ("missing end fitting",)),
        P("d/1", "ars_x", "bent_tube 3 deg", True, ()),  # missed
        P("d/2", "ars_y", "bent_tube 8 deg", False, ("bent tube",)),
        P("d/3", "ars_y", "missing_end_fitting b", False, ("missing end fitting",)),
    ]
    figures = bench.report(results)
    assert figures == {"caught": 0.75, "rejected": 0.02, "defective": 4, "good": 50}
    out = capsys.readouterr().out
    wrong = out.split("wrong decisions:")[1].split("\n\n")[0].strip().splitlines()
    assert [line.split()[0] for line in wrong] == ["v/49", "d/1"]
    assert "bent_tube 3 deg" in out and "defective parts caught: 75.0% of 4" in out


def test_mask_rcnn_segments_a_presented_strut_as_the_node_does_with_the_frames_depth(bench):
    """The node's frames carry their depth, and its segmenter cuts and joins the thin parts' regions
    on it (node.yaml ``segmentation.depth_split``): the bench's detections are those, not the RGB
    alone's (without the depth, a held diagonal whose tube the jaws cross is judged by two pieces
    the node would have joined)."""
    scene_mod = pytest.importorskip("tlt_sim.model.scene")
    from tlt_vision.camera_frame import CameraFrame

    config = load_config()
    assert config.raw["segmentation"]["depth_split"], "node.yaml cuts no thin part on the depth"
    mission = load_mission(ROOT / "missions" / "two_bay.yaml")
    detect = bench.detector("mask_rcnn")
    name = next(n for n, kind in bench.struts(mission) if kind == "diagonal")
    with scene_mod.Scene(mission=mission, scenario=bench.scenario(mission, [8.0])) as scene:
        frame = bench.present(
            scene,
            scene.part(name),
            "ars_x",
            bench.inspection_joints()["ars_x"],
            np.random.default_rng(1200),
            bench.Jitter(),
        )
    camera = bench.CAMERAS["ars_x"]

    def node_masks(**images):
        k = frame.intrinsics
        node_frame = CameraFrame(camera, 0.0, f"{camera}_optical", k, k.matrix, images)
        return masks(detect.segmenter.detect(node_frame))

    def masks(detections):
        return [(d.object_class, round(d.score, 4), int(d.mask.sum())) for d in detections]

    bench_masks = masks(detect(frame, camera))
    assert bench_masks == node_masks(rgb=frame.rgb, depth=frame.depth)
    assert bench_masks != node_masks(rgb=frame.rgb)
