"""The candidate-weights comparison: its figures are the benchmarks' own, read from their JSON, its
goals and differences point the right way, and a whole run on a small held-out set gives a table."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
WEIGHTS = ROOT / "models/vision/mask_rcnn.pt"


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("vision_candidate")


def _vision_json(
    views: int,
    views_certified: int,
    certified: int,
    add_s_ok: int,
    ap: float,
    shown: tuple[int, int] = (0, 0),
) -> dict:
    poses = {
        "posed": certified + 5,
        "certified": certified,
        "views": views,
        "views_certified": views_certified,
        "views_shown": shown[0],
        "views_shown_certified": shown[1],
        "add_s_ok": add_s_ok,
        "median_rotation_deg": 0.1,
        "median_translation_mm": 0.4,
    }
    return {"mask_ap50_node": {"mean": ap, "per_class": {}}, "poses": poses}


def test_the_table_reads_the_vision_benchs_figures_and_marks_the_goals(bench):
    row = bench.vision_figures(
        _vision_json(200, views_certified=192, certified=195, add_s_ok=190, ap=0.91, shown=(220, 198))
    )
    assert row == {
        "ap50": 0.91,
        "certified": 0.96,
        "shown": 0.9,
        "add_s_ok": pytest.approx(190 / 195),
        "views": 200,
        "views_shown": 220,
    }
    # Segmentation's losses counted, the same poses fall short.
    assert bench.goals_met(row) == {"ap50": True, "certified": True, "shown": False, "add_s_ok": True}
    short = bench.vision_figures(_vision_json(100, views_certified=94, certified=94, add_s_ok=80, ap=0.84))
    assert bench.goals_met(short) == {"ap50": False, "certified": False, "add_s_ok": False}
    # Nothing certified: no share to give, and no goal judged on it.
    none = bench.vision_figures(_vision_json(views=0, views_certified=0, certified=0, add_s_ok=0, ap=0.5))
    assert none["certified"] is None and none["shown"] is None and none["add_s_ok"] is None
    assert bench.goals_met(none) == {"ap50": False}
    # Good parts rejected: lower is better, so at most the goal meets it.
    assert bench.goals_met({"caught": 1.0, "rejected": 0.02}) == {"caught": True, "rejected": True}
    assert bench.goals_met({"caught": 0.98, "rejected": 0.03}) == {"caught": False, "rejected": False}


def test_a_positive_difference_is_always_a_gain(bench):
    diff = bench.compare(
        {"ap50": 0.90, "certified": 0.95, "rejected": 0.0},
        {"ap50": 0.85, "certified": 0.96, "rejected": 0.05},
    )
    assert diff == pytest.approx({"ap50": 0.05, "certified": -0.01, "rejected": 0.05})


def test_the_sets_are_pooled_by_their_views_and_their_ap_averaged(bench):
    rows = {
        "seed 1": {"a": {"ap50": 0.8, "certified": 1.0, "views": 100, "shown": 0.5, "views_shown": 100}},
        "seed 2": {"a": {"ap50": 0.9, "certified": 0.5, "views": 300, "shown": 1.0, "views_shown": 100}},
    }
    assert bench.pooled(rows, ["a"])["a"] == pytest.approx({"ap50": 0.85, "certified": 0.625, "shown": 0.75})
    # A set measured before the second count: pooled over the sets that have it.
    rows["seed 3"] = {"a": {"ap50": 0.7, "certified": 1.0, "views": 400, "shown": None, "views_shown": 0}}
    assert bench.pooled(rows, ["a"])["a"]["shown"] == pytest.approx(0.75)
    text = bench.table(rows, ["a"], ["ap50", "certified"])
    assert "0.800 --" in text and "100.0 % ok" in text and "50.0 % --" in text


def test_a_run_compares_two_weights_on_a_small_held_out_set(bench, tmp_path, capsys):
    """Every benchmark for real, on two rendered images of one seed and no inspection: the shipped
    weights against themselves come out equal, figure for figure."""
    pytest.importorskip("tlt_sim.model.scene")
    rc = bench.main(
        [
            "--weights",
            str(WEIGHTS),
            "--seeds",
            "900",
            "--count",
            "2",
            "--inspection-seeds",
            "--jobs",
            "2",
            "--work",
            str(tmp_path),
        ]
    )
    out = capsys.readouterr().out
    assert rc == 0, out
    summary = json.loads((tmp_path / "summary.json").read_text())
    seed = summary["rows"]["vision"]["seed 900"]
    assert seed["candidate"] == seed["current"]
    assert 0.0 < seed["candidate"]["ap50"] <= 1.0 and seed["candidate"]["views"] > 0
    figures = json.loads((tmp_path / "candidate_900.json").read_text())
    assert figures["images"] == 2 and figures["poses"]["views"] == seed["candidate"]["views"]
    # The second count is made on the model's masks too: the twin's masks of the matched parts.
    assert figures["poses"]["views_shown"] > 0
    assert "mask AP50 +0.000" in out and "seed 900" in out
    # The rendered set is kept for the next run; a missing weights file is refused up front.
    assert (tmp_path / "held_out_900_2" / "index.json").exists()
    with pytest.raises(SystemExit):
        bench.main(["--weights", str(tmp_path / "missing.pt"), "--work", str(tmp_path)])
