"""scripts/train_mask_rcnn.sh on the CPU at toy size: it renders the shards (with the seeds and
scene mix asked for) and the validation set, trains within its budget and leaves the weights,
figures and logs; a second run trains on the first one's images from its weights, in two processes
sharing each step, with sensor noise and blur added to its images, validated on the model's masks
alone where the first was validated on the masks as the node makes them; a device it cannot use stops it
at the smoke test, before anything is rendered at scale."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "train_mask_rcnn.sh"
TOY = {
    "COUNT": "4", "SHARDS": "2", "VAL": "2", "DEVICE": "cpu", "WORKERS": "1", "BUDGET_MIN": "1",
    "EPOCHS": "1", "BATCH": "2", "PYTHON": sys.executable,
    "MODEL": "--max-size 96 --config fpn_channels=16 --config backbone_channels=[8,8,16,16]",
}  # fmt: skip


def _run(tmp_path: Path, **settings: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, **TOY, "DATA_DIR": str(tmp_path / "data"), **settings}
    return subprocess.run(
        ["bash", str(SCRIPT), str(tmp_path / "out")], capture_output=True, text=True, timeout=300, env=env
    )


def test_renders_shards_and_trains_within_the_budget(tmp_path):
    result = _run(tmp_path, SEED_BASE="1500", SCENES="held=0.5 feeder=0.5")
    assert result.returncode == 0, result.stdout + result.stderr
    out = tmp_path / "out"
    assert "rendered 4 training images in 2 shards" in result.stdout
    assert sorted(p.name for p in out.iterdir()) == [
        "mask_rcnn.json", "mask_rcnn.pt", "mask_rcnn_curves.png", "mask_rcnn_samples.png", "render.log",
        "smoke.log", "train.log"]  # fmt: skip
    figures = json.loads((out / "mask_rcnn.json").read_text())["extra"]["figures"]
    assert figures["train"] == [str(tmp_path / "data" / f"train_{k}") for k in range(2)]
    assert figures["images"] == 4 and figures["val_images"] == 2 and figures["device"] == "cpu"
    assert [r["seed"] for r in figures["train_recipes"]] == [1500, 1501]
    assert all(r["scenes"] == {"held": 0.5, "feeder": 0.5} for r in figures["train_recipes"])
    assert "epoch 1/1 val mask AP50" in (out / "train.log").read_text()
    assert figures["val_as"] == "as the node segments (config/vision/node.yaml)"  # NODE_CONFIG's default
    # A second run on the same images renders nothing and starts from the first run's weights; its
    # two processes (RANKS) take two images each of the step, and its smoke test trains with two.
    again = subprocess.run(
        ["bash", str(SCRIPT), str(tmp_path / "again")],
        capture_output=True,
        text=True,
        timeout=300,
        env={
            **os.environ,
            **TOY,
            "DATA_DIR": str(tmp_path / "data"),
            "RENDER": "0",
            "INIT": str(out / "mask_rcnn.pt"),
            "RANKS": "2",
            "NOISE": "4",
            "BLUR": "1.5",
            "NODE_CONFIG": "",
        },
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert "rendering 4 images" not in again.stdout
    assert "rendered 4 training images in 2 shards" in again.stdout
    log = (tmp_path / "again" / "train.log").read_text()
    assert f"initialised from {out / 'mask_rcnn.pt'}" in log
    assert "2 processes sharing each step's 4 images" in log
    assert "2 processes sharing each step's 2 images" in (tmp_path / "again" / "smoke.log").read_text()
    # What a camera adds, as asked, recorded with the weights; the first run's had none.
    second = json.loads((tmp_path / "again" / "mask_rcnn.json").read_text())["extra"]["figures"]
    assert (second["augment"]["noise"], second["augment"]["blur"]) == (4.0, 1.5)
    assert second["val_as"] == "the model alone"
    assert (figures["augment"]["noise"], figures["augment"]["blur"]) == (0.0, 0.0)


def test_a_device_it_cannot_use_stops_it_at_the_smoke_test(tmp_path):
    result = _run(tmp_path, DEVICE="nope")
    assert result.returncode != 0
    assert "--device nope" in result.stderr and "smoke test passed" not in result.stdout
    assert not (tmp_path / "data" / "train_0").exists()
