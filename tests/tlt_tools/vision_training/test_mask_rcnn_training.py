"""The Mask R-CNN training command on a tiny set of drawn shapes: it learns, saves weights the node
loads, resumes, draws its figures, evaluates, and refuses bad input with exit status 2."""

import contextlib
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from tlt_tools.vision_training.data_parallel import Ranks
from tlt_tools.vision_training.dataset import ImageSet, Sample, write_index, write_sample
from tlt_tools.vision_training.mask_rcnn import main, parse_args
from tlt_tools.vision_training.mask_rcnn_data import Augment, augment, gaussian_blur, load_sample, open_set
from tlt_tools.vision_training.mask_rcnn_evaluation import evaluate
from tlt_tools.vision_training.mask_rcnn_training import (
    build_config,
    epochs_at_pace,
    epochs_within,
    learning_rate,
    pace_probe_step,
    parse_overrides,
)

from tlt_vision.ops.boxes import boxes_from_masks
from tlt_vision.segmentation.config import CLASSES
from tlt_vision.segmentation.inference import detect_rgb, load_mask_rcnn
from tlt_vision.segmentation.model import MaskRCNN
from tlt_vision.weights import WeightsError, read_manifest

SIZE = 48
TINY = {
    "backbone_channels": [8, 8, 16, 16], "fpn_channels": 16, "representation": 32, "mask_convs": 1,
    "rpn_pre_nms_top_n": 100, "rpn_post_nms_top_n_train": 50, "rpn_post_nms_top_n_test": 30,
    "rpn_batch_per_image": 64, "roi_batch_per_image": 32,
}  # fmt: skip
CONFIG_ARGS = [a for k, v in TINY.items() for a in ("--config", f"{k}={json.dumps(v)}")]
EPOCHS = 12
SEED = 0
BLOCK = CLASSES.index("corner_joint") + 1


def write_set(root, n, seed, classes=CLASSES):
    """``n`` images of one blue block (class corner_joint) on a dark noisy background: a problem a
    0.05 M-parameter model learns in a few dozen steps, so the test is about the command."""
    root.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    files = []
    for i in range(n):
        rgb = rng.integers(0, 50, size=(SIZE, SIZE, 3), dtype=np.uint8)
        half = int(rng.integers(7, 12))
        cx, cy = rng.integers(half + 1, SIZE - half - 1, size=2)
        mask = np.zeros((SIZE, SIZE), dtype=bool)
        mask[cy - half : cy + half, cx - half : cx + half] = True
        rgb[mask] = (40, 90, 190)
        sample = Sample(
            rgb=rgb, depth=np.ones((SIZE, SIZE), np.float32), masks=mask[None], labels=np.array([BLOCK]),
            names=np.array(["block"]), poses=np.eye(4)[None], defects=np.array([""]), intrinsics=np.eye(3),
        )  # fmt: skip
        name = f"{i:05d}.npz"
        write_sample(root / name, sample)
        files.append(name)
    write_index(root, list(classes), SIZE, SIZE, files, {"drawn": "blocks"})
    return root


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    base = tmp_path_factory.mktemp("mask_rcnn")
    train, val = write_set(base / "train", 16, seed=1), write_set(base / "val", 6, seed=2)
    out = base / "out" / "mrcnn.pt"
    args = ["--train", str(train), "--val", str(val), "--out", str(out), "--epochs", str(EPOCHS),
            "--batch", "4", "--lr", "5e-3", "--seed", str(SEED), "--threads", "1", "--log-every", "2",
            *CONFIG_ARGS]  # fmt: skip
    # The same model before training, for the AP it starts from.
    torch.manual_seed(SEED)
    before = evaluate(MaskRCNN(build_config(TINY)), open_set(val, CLASSES), None)["map"]
    return {"base": base, "train": train, "val": val, "out": out, "args": args, "before": before}


@pytest.fixture(scope="module")
def run(trained):
    buf = io.StringIO()  # capsys is per test; the run is shared by the module's tests
    with contextlib.redirect_stdout(buf):
        rc = main(trained["args"])
    return {**trained, "rc": rc, "text": buf.getvalue()}


def test_training_reduces_the_loss_raises_ap50_and_writes_its_outputs(run):
    assert run["rc"] == 0
    text = run["text"]
    assert f"epoch 1/{EPOCHS} step 2/4" in text and "img/s" in text and "ETA" in text
    assert "rpn_obj" in text and "mask" in text
    assert f"epoch {EPOCHS}/{EPOCHS} val mask AP50" in text and "corner_joint" in text
    manifest = read_manifest(run["out"])
    assert manifest["kind"] == "mask_rcnn" and manifest["classes"] == list(CLASSES)
    assert manifest["settings"]["model"]["fpn_channels"] == 16 and manifest["settings"]["max_size"] is None
    figures = manifest["extra"]["figures"]
    history = figures["history"]
    assert history[-1]["train_losses"]["total"] < 0.7 * history[0]["train_losses"]["total"]
    best = max(h["val_map"] for h in history)
    assert figures["val_map"] == best and figures["images"] == 16 and figures["seconds"] > 0
    assert set(figures["val_ap50"]) == {"corner_joint"}  # the only class with ground truth
    assert best >= run["before"] + 0.5, (run["before"], [h["val_map"] for h in history])
    stem = run["out"].with_suffix("")
    for suffix in ("_curves.png", "_samples.png"):
        data = (stem.parent / f"{stem.name}{suffix}").read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert (stem.parent / f"{stem.name}_checkpoint.pt").is_file()


def test_saved_weights_load_in_the_node_and_a_mismatched_manifest_is_refused(run, tmp_path):
    from tlt_vision.camera_frame import CameraFrame
    from tlt_vision.segmentation_source import MaskRcnnSegmenter

    # A dozen epochs on sixteen images leave the class scores near 0.3 (of six classes).
    seg = MaskRcnnSegmenter.load(run["out"], min_score=0.2)
    sample = open_set(run["val"], CLASSES)[0]
    frame = CameraFrame("zed_1", 0.0, "zed_1_optical", None, np.eye(3), {"rgb": sample.rgb})
    dets = seg.detect(frame)
    assert dets and all(d.mask.shape == (SIZE, SIZE) for d in dets)
    assert max(dets, key=lambda d: d.score).object_class == "corner_joint"
    iou = max((d.mask & sample.masks[0]).sum() / (d.mask | sample.masks[0]).sum() for d in dets)
    assert iou > 0.5
    # A region of the frame looked at again (the strut's second look), as it is and enlarged:
    # masks of the whole frame's size, nothing outside the region, the part found where it is.
    rows, cols = np.nonzero(sample.masks[0])
    region = (max(0, cols.min() - 8), max(0, rows.min() - 8), cols.max() + 9, rows.max() + 9)
    closer = seg.detect_in(frame, region, 1.0)
    x0, y0, x1, y1 = region
    inside = np.zeros((SIZE, SIZE), dtype=bool)
    inside[y0:y1, x0:x1] = True
    assert closer and all(d.mask.shape == (SIZE, SIZE) and not (d.mask & ~inside).any() for d in closer)
    assert max((d.mask & sample.masks[0]).sum() / (d.mask | sample.masks[0]).sum() for d in closer) > 0.5
    enlarged = seg.detect_in(frame, region, 2.0)
    assert all(d.mask.shape == (SIZE, SIZE) and not (d.mask & ~inside).any() for d in enlarged)

    for key, value, reason in (("classes", list(reversed(CLASSES)), "classes"),
                               ("kind", "c3po_detector", "expected 'mask_rcnn'")):  # fmt: skip
        bad = tmp_path / f"{key}.pt"
        shutil.copy(run["out"], bad)
        manifest = json.loads(run["out"].with_suffix(".json").read_text())
        manifest[key] = value
        if key == "classes":
            manifest["settings"]["model"]["classes"] = value
        bad.with_suffix(".json").write_text(json.dumps(manifest))
        with pytest.raises(WeightsError, match=reason):
            MaskRcnnSegmenter.load(bad, min_score=0.5)
    wider = tmp_path / "wider.pt"
    shutil.copy(run["out"], wider)
    manifest = json.loads(run["out"].with_suffix(".json").read_text())
    manifest["settings"]["model"]["fpn_channels"] = 24
    wider.with_suffix(".json").write_text(json.dumps(manifest))
    with pytest.raises(WeightsError, match="expected"):
        load_mask_rcnn(wider)


def test_resume_continues_after_the_checkpoint_epoch(run, capsys):
    ckpt = run["out"].parent / "mrcnn_checkpoint.pt"
    args = [a if a != str(EPOCHS) else str(EPOCHS + 1) for a in run["args"]]
    assert main([*args, "--resume", str(ckpt)]) == 0
    text = capsys.readouterr().out
    assert f"after epoch {EPOCHS}" in text
    assert f"epoch {EPOCHS + 1}/{EPOCHS + 1} step 4/4" in text and "epoch 1/" not in text
    state = torch.load(ckpt, weights_only=True)
    assert state["epoch"] == EPOCHS + 1 and len(state["history"]) == EPOCHS + 1
    assert [h["epoch"] for h in state["history"]] == list(range(1, EPOCHS + 2))
    # Other settings than the checkpoint's are refused.
    other = [*run["args"], "--config", "fpn_channels=8", "--resume", str(ckpt)]
    assert main(other) == 2
    assert "fpn_channels" in capsys.readouterr().err


def test_init_starts_from_trained_weights_and_a_new_head_starts_fresh(run, tmp_path, capsys):
    out = tmp_path / "init.pt"
    semantic = ["--config", 'semantic_classes=["strut_tube"]', "--config", "semantic_channels=8"]
    args = [*run["args"][: run["args"].index("--out")], "--out", str(out), "--epochs", "1", "--batch", "4",
            "--threads", "1", *CONFIG_ARGS, *semantic]  # fmt: skip
    assert main([*args, "--init", str(run["out"])]) == 0
    text = capsys.readouterr().out
    assert f"initialised from {run['out']}; 12 tensors fresh, from semantic." in text
    # After one epoch at a warm-up learning rate it still finds the blocks the first run learned.
    first = read_manifest(run["out"])["extra"]["figures"]["val_map"]
    assert read_manifest(out)["extra"]["figures"]["val_map"] >= first - 0.2
    assert main([*args, "--init", str(tmp_path / "none.pt")]) == 2
    assert "none.pt" in capsys.readouterr().err
    assert (
        main(
            [
                *args,
                "--init",
                str(run["out"]),
                "--config",
                "fpn_channels=8",
                "--config",
                "backbone_channels=[4,4,4,4]",
                "--config",
                "representation=8",
            ]
        )
        == 2
    )
    assert "of the model's parameters (another --config?)" in capsys.readouterr().err


def test_evaluate_prints_ap_per_class_and_time(run, capsys):
    assert main(["--evaluate", str(run["out"]), "--val", str(run["val"]), "--threads", "1"]) == 0
    text = capsys.readouterr().out
    figures = read_manifest(run["out"])["extra"]["figures"]
    assert f"corner_joint   AP50 {figures['val_ap50']['corner_joint']:.3f}" in text
    assert f"mean           AP50 {figures['val_map']:.3f}" in text
    assert "strut_tube     AP50 -" in text and "ms per image" in text


def test_validation_as_the_node_segments_is_named_in_the_log_manifest_and_evaluation(
    trained, tmp_path, capsys
):
    """``--node-config``: the validation AP is that of the node's masks (the shipped model's case is
    tests/tlt_vision/segmentation/test_shipped_mask_rcnn.py), and every report says which it is."""
    node_yaml = str(Path(__file__).resolve().parents[3] / "config" / "vision" / "node.yaml")
    out = tmp_path / "w.pt"
    args = [
        "--train",
        str(trained["train"]),
        "--val",
        str(trained["val"]),
        "--out",
        str(out),
        "--epochs",
        "1",
        "--batch",
        "4",
        "--threads",
        "1",
        "--node-config",
        node_yaml,
        *CONFIG_ARGS,
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert f"val {trained['val']} (6 images, as the node segments ({node_yaml}))" in text
    assert read_manifest(out)["extra"]["figures"]["val_as"] == f"as the node segments ({node_yaml})"
    # Its epochs were chosen by the node's masks: resumed, the next ones must be too.
    resumed = ["--train", str(trained["train"]), "--val", str(trained["val"]), "--out", str(out),
               "--epochs", "2", "--batch", "4", "--threads", "1", *CONFIG_ARGS,
               "--resume", str(tmp_path / "w_checkpoint.pt")]  # fmt: skip
    assert main(resumed) == 2
    err = capsys.readouterr().err
    assert f"validated as the node segments ({node_yaml}), this run's would be the model alone" in err
    assert main(["--evaluate", str(out), "--val", str(trained["val"]), "--node-config", node_yaml]) == 0
    assert f"as the node segments ({node_yaml})" in capsys.readouterr().out
    assert main(["--evaluate", str(out), "--val", str(trained["val"])]) == 0
    assert "the model alone" in capsys.readouterr().out
    bad = tmp_path / "node.yaml"
    text = Path(node_yaml).read_text()
    assert "\n  min_score: 0.3\n" in text
    bad.write_text(text.replace("\n  min_score: 0.3\n", "\n  min_score: 2\n"))
    refused = tmp_path / "refused.pt"
    assert main([*args, "--out", str(refused), "--node-config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"--node-config {bad}: " in err and "segmentation.min_score" in err, err
    assert not refused.exists()  # refused before training, not after an epoch
    with pytest.raises(SystemExit):
        parse_args(["--train", str(trained["train"]), "--node-config", node_yaml])
    assert "--node-config needs --val" in capsys.readouterr().err


def test_bad_inputs_exit_2_naming_the_path(tmp_path, capsys):
    out = str(tmp_path / "w.pt")
    assert main(["--train", str(tmp_path), "--out", out]) == 2
    assert f"{tmp_path / 'index.json'}: no such file" in capsys.readouterr().err
    other = write_set(tmp_path / "other", 1, seed=0, classes=["a", "b"])
    assert main(["--train", str(other), "--out", out]) == 2
    err = capsys.readouterr().err
    assert str(other / "index.json") in err and "differ from the model's" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    write_index(empty, list(CLASSES), SIZE, SIZE, [], {})
    assert main(["--train", str(empty), "--out", out]) == 2
    assert "no images" in capsys.readouterr().err
    assert main(["--evaluate", str(tmp_path / "none.pt"), "--val", str(other)]) == 2
    assert "weights file not found" in capsys.readouterr().err
    assert main(["--train", str(other), "--out", out, "--config", "nope=1"]) == 2
    assert "unknown Mask R-CNN settings: nope" in capsys.readouterr().err
    assert parse_overrides(["backbone_channels=[8,8,16,16]"]) == {"backbone_channels": [8, 8, 16, 16]}


def test_flip_keeps_boxes_on_their_masks_and_full_size_detections_from_a_downscaled_model():
    rng = np.random.default_rng(0)
    masks = torch.zeros(2, 20, 30, dtype=torch.bool)
    masks[0, 2:5, 3:10] = True
    masks[1, 10:18, 20:29] = True
    target = {"boxes": boxes_from_masks(masks), "labels": torch.tensor([1, 2]), "masks": masks}
    assert target["boxes"].tolist() == [[3, 2, 10, 5], [20, 10, 29, 18]]
    image = torch.rand(3, 20, 30)
    flipped, t = augment(image, target, Augment(flip=1.0, brightness=0.0, contrast=0.0), rng)
    assert torch.equal(t["boxes"], boxes_from_masks(t["masks"])) and torch.allclose(flipped, image.flip(-1))
    torch.manual_seed(0)
    model = MaskRCNN(build_config({**TINY, "score_threshold": 0.0}))
    det = detect_rgb(model, (np.random.default_rng(1).random((60, 90, 3)) * 255).astype(np.uint8), 45)
    assert det["masks"].shape[1:] == (60, 90) and len(det["boxes"]) > 0
    assert (det["boxes"][:, 2] <= 90 + 1e-3).all() and (det["boxes"][:, 3] <= 60 + 1e-3).all()


def test_a_gaussian_blur_spreads_a_point_as_its_hand_computed_kernel():
    image = torch.zeros(3, 15, 15)
    image[:, 7, 7] = 1.0
    out = gaussian_blur(image, 1.0)
    taps = 1.0 + 2.0 * sum(np.exp(-0.5 * x * x) for x in (1, 2, 3))  # radius ceil(3 sigma)
    assert out[0, 7, 7].item() == pytest.approx(1.0 / taps**2, rel=1e-5)
    assert out[1, 7, 8].item() == pytest.approx(np.exp(-0.5) / taps**2, rel=1e-5)
    assert out.sum().item() == pytest.approx(3.0, rel=1e-5)  # nothing lost or made
    assert torch.equal(gaussian_blur(image, 0.2), image)  # under a third of a pixel: one tap


def test_sensor_noise_and_blur_change_the_colours_only_and_are_off_by_default():
    masks = torch.zeros(1, 40, 60, dtype=torch.bool)
    masks[0, 10:30, 20:40] = True
    target = {"boxes": boxes_from_masks(masks), "labels": torch.tensor([1]), "masks": masks}
    image = torch.full((3, 40, 60), 0.3)
    image[:, :, 30:] = 0.7  # a step edge, far from 0 and 1 so nothing is clipped
    still = Augment(flip=0.0, brightness=0.0, contrast=0.0)

    noisy, t = augment(
        image, target, Augment(flip=0.0, brightness=0.0, contrast=0.0, noise=8.0), np.random.default_rng(3)
    )
    residual = (noisy - image).std().item() * 255.0
    assert 0.5 < residual < 8.0
    assert torch.equal(t["masks"], masks) and torch.equal(t["boxes"], target["boxes"])
    blurred, t = augment(
        image, target, Augment(flip=0.0, brightness=0.0, contrast=0.0, blur=2.0), np.random.default_rng(3)
    )
    row = blurred[0, 20]
    assert 0.3 < row[29].item() < row[30].item() < 0.7  # the edge softened, the flats kept
    assert row[0].item() == pytest.approx(0.3) and row[-1].item() == pytest.approx(0.7)
    assert torch.equal(t["masks"], masks)

    # Off, they draw nothing: a recipe's images are those it trained on before the options came.
    rng, reference = np.random.default_rng(4), np.random.default_rng(4)
    augmented, _ = augment(image, target, still, rng)
    reference.random(), reference.uniform(0.0, 0.0), reference.uniform(0.0, 0.0)
    assert rng.bit_generator.state == reference.bit_generator.state and torch.allclose(augmented, image)
    assert Augment().noise == Augment().blur == 0.0


@pytest.mark.parametrize(("option", "value"), [("--sensor-noise", "100"), ("--blur", "-1")])
def test_sensor_noise_and_blur_out_of_range_are_refused_naming_the_option(option, value, capsys):
    with pytest.raises(SystemExit) as exit_:
        parse_args(["--train", "x", option, value])
    assert exit_.value.code == 2 and f"{option} {float(value):g}" in capsys.readouterr().err


def test_several_training_sets_train_as_one_and_loader_workers_see_the_same_images(tmp_path, capsys):
    # One set split in two (as sets rendered in parallel are) and loaded by two worker processes
    # trains exactly as the whole set loaded in the training process: the order depends on the seed
    # and epoch, each image's augmentation on the seed, epoch and image.
    whole = write_set(tmp_path / "whole", 16, seed=1)
    halves = []
    for k, name in enumerate(("a", "b")):
        half = tmp_path / name
        half.mkdir()
        files = [f"{i:05d}.npz" for i in range(8)]
        for i, file in enumerate(files):
            shutil.copy(whole / f"{8 * k + i:05d}.npz", half / file)
        write_index(half, list(CLASSES), SIZE, SIZE, files, {"half": name})
        halves.append(half)
    common = ["--epochs", "1", "--batch", "4", "--seed", "3", "--threads", "1", *CONFIG_ARGS]
    runs = {}
    for name, sets, workers in (("one", [whole], "0"), ("two", halves, "2")):
        out = tmp_path / name / "w.pt"
        assert main(["--train", *map(str, sets), "--out", str(out), "--workers", workers, *common]) == 0
        runs[name] = read_manifest(out)["extra"]["figures"]
    assert "(16 images)" in capsys.readouterr().out
    assert runs["two"]["train"] == [str(p) for p in halves] and runs["two"]["images"] == 16
    # How each set was rendered, not only where it lay (scratch space, gone after the run).
    assert runs["two"]["train_recipes"] == [{"half": "a", "images": 8}, {"half": "b", "images": 8}]
    one, two = (runs[n]["history"][0]["train_losses"] for n in ("one", "two"))
    assert one == pytest.approx(two, rel=1e-5)
    assert main(["--train", str(whole), "--out", str(tmp_path / "w.pt"), "--device", "nope"]) == 2
    assert "--device nope" in capsys.readouterr().err


def test_a_time_budget_trains_the_epochs_that_fit(tmp_path, capsys):
    assert epochs_within(600.0, 100.0, 1, 1, 20) == 6  # 100 s an epoch: five more fit
    assert epochs_within(600.0, 100.0, 1, 1, 4) == 4  # never more than asked
    assert epochs_within(60.0, 100.0, 1, 1, 20) == 1  # over budget already: stop after this one
    assert epochs_within(600.0, 100.0, 2, 3, 20) == 3 + 10  # resumed: 50 s an epoch of this run
    images = write_set(tmp_path / "set", 4, seed=1)
    out = tmp_path / "w.pt"
    args = [
        "--train",
        str(images),
        "--out",
        str(out),
        "--epochs",
        "5",
        "--time-budget-min",
        "1e-6",
        "--threads",
        "1",
        *CONFIG_ARGS,
    ]
    assert main(args) == 0
    assert "time budget 1e-06 min: 1 epochs fit, not 5" in capsys.readouterr().out
    assert torch.load(out.parent / "w_checkpoint.pt", weights_only=True)["epoch"] == 1


def test_an_epoch_longer_than_the_budget_decays_the_learning_rate_over_itself(tmp_path, capsys):
    # Judged only after the first epoch, an epoch longer than the budget would run at the peak rate
    # and end there (as a lent GPU's first epoch can); judged early in it, it decays.
    assert pace_probe_step(375) == 20 and pace_probe_step(1000) == 50 and pace_probe_step(8) == 7
    assert pace_probe_step(1) == 0  # a one-step epoch is judged at its end, as before
    assert epochs_at_pace(360.0, 219.0, 0, 40) == 1  # that run: one epoch fits
    assert epochs_at_pace(360.0, 100.0, 0, 40) == 3 and epochs_at_pace(360.0, 100.0, 0, 2) == 2
    assert epochs_at_pace(360.0, 1000.0, 4, 40) == 5  # resumed after 4: at least one more
    images = write_set(tmp_path / "set", 16, seed=1)
    args = [
        "--train",
        str(images),
        "--out",
        str(tmp_path / "w.pt"),
        "--epochs",
        "5",
        "--batch",
        "2",
        "--lr",
        "5e-3",
        "--time-budget-min",
        "1e-6",
        "--threads",
        "1",
        "--log-every",
        "8",
        *CONFIG_ARGS,
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "time budget 1e-06 min: 1 epochs fit, not 5 (from the first 7 steps)" in text
    # The last step's rate is the one-epoch schedule's, well under the peak.
    assert "epoch 1/1 step 8/8 " in text and f"lr {learning_rate(7, 8, 5e-3):.1e}" in text


def test_the_loader_drops_instances_under_the_minimum_area_and_takes_an_image_with_none(tmp_path):
    """An image of the twin can show no part (a feeder scene looking past the racks): it trains as
    all background, and a sliver of a part under ``min_area`` pixels is dropped, not trained on."""
    empty = np.zeros((0, SIZE, SIZE), dtype=bool)
    sliver = np.zeros((2, SIZE, SIZE), dtype=bool)
    sliver[0, 10:20, 10:20] = True  # 100 px
    sliver[1, 30, 30:33] = True  # 3 px
    files = []
    for i, masks in enumerate((empty, sliver)):
        n = len(masks)
        write_sample(tmp_path / f"{i}.npz", Sample(
            rgb=np.zeros((SIZE, SIZE, 3), np.uint8), depth=np.ones((SIZE, SIZE), np.float32), masks=masks,
            labels=np.full(n, BLOCK), names=np.array(["block"] * n), poses=np.tile(np.eye(4), (n, 1, 1)),
            defects=np.array([""] * n), intrinsics=np.eye(3)))  # fmt: skip
        files.append(f"{i}.npz")
    write_index(tmp_path, list(CLASSES), SIZE, SIZE, files, {"drawn": "slivers"})
    images = ImageSet(tmp_path)
    image, target = load_sample(images, 0, None, min_area=4)
    assert image.shape == (3, SIZE, SIZE)
    assert target["boxes"].shape == (0, 4) and target["masks"].shape == (0, SIZE, SIZE)
    _, target = load_sample(images, 1, None, min_area=4)
    assert target["labels"].tolist() == [BLOCK]
    assert target["boxes"].tolist() == [[10.0, 10.0, 20.0, 20.0]]


def test_each_process_takes_its_own_share_of_every_step():
    order = list(range(100, 118))  # 18 images
    shares = [Ranks(r, 2).batches(order, 4) for r in range(2)]
    assert shares[0] == [[100, 101, 102, 103], [108, 109, 110, 111]]
    assert shares[1] == [[104, 105, 106, 107], [112, 113, 114, 115]]
    # Two images would leave one process without a whole batch: they wait for another epoch.
    assert len(shares[0]) == len(shares[1]) == 2
    alone = Ranks().batches(order, 4)
    assert [i for b in alone for i in b] == order and alone[-1] == [116, 117]


def test_several_processes_train_one_model_on_their_shares_of_each_step(trained, tmp_path, capfd):
    # Two processes of two images a step each: four a step, as the one-process run's --batch 4, and
    # the replicas' weights checked equal after every epoch (else the run fails).
    out = tmp_path / "w.pt"
    args = ["--train", str(trained["train"]), "--val", str(trained["val"]), "--out", str(out),
            "--epochs", str(EPOCHS), "--batch", "2", "--ranks", "2", "--lr", "5e-3", "--seed", str(SEED),
            "--threads", "1", "--log-every", "2", *CONFIG_ARGS]  # fmt: skip
    assert main(args) == 0
    text = capfd.readouterr().out
    assert text.count("(16 images)") == 1  # only the leader prints
    assert "2 processes sharing each step's 4 images" in text and f"epoch {EPOCHS}/{EPOCHS} step 4/4" in text
    figures = read_manifest(out)["extra"]["figures"]
    assert figures["processes"] == 2 and figures["batch"] == 2
    history = figures["history"]
    assert history[-1]["train_losses"]["total"] < 0.7 * history[0]["train_losses"]["total"]
    assert max(h["val_map"] for h in history) >= trained["before"] + 0.5
    assert main([*args[: -len(CONFIG_ARGS)], "--batch", "9", *CONFIG_ARGS]) == 2
    assert "16 images, fewer than --batch 9 times --ranks 2" in capfd.readouterr().err
    # Weights that cannot be used are refused once, before any process starts.
    assert main([*args, "--init", str(tmp_path / "none.pt")]) == 2
    err = capfd.readouterr().err
    assert err.count("none.pt") == 1 and "Traceback" not in err


def test_a_bad_input_one_process_meets_while_training_ends_the_run_with_status_2(tmp_path, capfd):
    # Image sizes are only seen when a batch is stacked, inside one of the processes: it says what
    # is wrong as the one-process command does, and the others are stopped.
    small = tmp_path / "small"
    small.mkdir()
    files = []
    for i in range(8):
        rgb = np.zeros((40, 40, 3), np.uint8)
        write_sample(small / f"{i:05d}.npz", Sample(
            rgb=rgb, depth=np.ones((40, 40), np.float32), masks=np.zeros((0, 40, 40), bool),
            labels=np.zeros(0, int), names=np.array([], str), poses=np.zeros((0, 4, 4)),
            defects=np.array([], str), intrinsics=np.eye(3)))  # fmt: skip
        files.append(f"{i:05d}.npz")
    write_index(small, list(CLASSES), 40, 40, files, {"drawn": "nothing"})
    sets = [str(write_set(tmp_path / "big", 8, seed=1)), str(small)]
    args = ["--train", *sets, "--out", str(tmp_path / "w.pt"), "--epochs", "1", "--batch", "4",
            "--ranks", "2", "--threads", "1", *CONFIG_ARGS]  # fmt: skip
    assert main(args) == 2
    err = capfd.readouterr().err
    assert "error: " in err and "images of different sizes" in err and "Traceback" not in err
