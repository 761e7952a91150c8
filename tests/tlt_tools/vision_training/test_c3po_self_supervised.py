"""Self-supervised C-3PO: clouds read from rendered scenes as the node would see them, pseudo-labels
from certified poses only that teach a detector the truth it never sees, the best epoch kept, the
stopping rules, and the command against a rendered set (weights the node loads, a plot, errors)."""

import copy

import numpy as np
import pytest
import torch
from tlt_tools.vision_training.c3po_self_supervised import (
    SceneCloud,
    SelfSupervisedConfig,
    evaluate,
    main,
    scene_clouds,
    train_epoch,
    train_self_supervised,
)
from tlt_tools.vision_training.c3po_supervised import SupervisedConfig, train_supervised
from tlt_tools.vision_training.dataset import ImageSet, write_index

from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import models_for_mission
from tlt_vision.cad.views import random_rotation, synthetic_view
from tlt_vision.ops.registration import transform
from tlt_vision.pipeline import PartPipeline
from tlt_vision.pose.corrector import CorrectorConfig
from tlt_vision.pose.detector import symmetric_keypoint_loss
from tlt_vision.pose.detector_weights import load_detector
from tlt_vision.pose.estimator import PoseEstimator
from tlt_vision.weights import read_manifest

pytest.importorskip("tlt_sim.model.scene")
from tlt_tools.vision_training.render_dataset import main as render

MISSION = "missions/one_bay.yaml"
CORRECTOR = CorrectorConfig(max_iterations=200, step=0.02, decay=0.98, patience=20, refine_iterations=30)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("scenes")
    assert render(["--out", str(out), "--count", "3", "--seed", "3"]) == 0
    return out


@pytest.fixture(scope="module")
def mission():
    return load_mission(MISSION)


def _views(model, n, rng, points=128):
    out = []
    while len(out) < n:
        rot = random_rotation(rng)
        t = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(0.6, 1.2)])
        view = synthetic_view(model, rot, t, points, rng, noise=0.001)
        if len(view) < 32:
            continue
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rot, t
        out.append(SceneCloud(view.astype(np.float32), "synthetic", pose))
    return out


def _weak_estimator(mission, name):
    """A detector after a token supervised stage (32 views, one epoch): the corrector does most of
    the work, so its certified poses are good labels and the detector has much to learn."""
    model = models_for_mission(mission)[name]
    threshold = mission.inspection["chamfer_thresholds"][model.object_class]
    cfg = SupervisedConfig(train_samples=32, val_samples=4, epochs=1, certify_samples=0, width=16, points=128)
    det, _ = train_supervised(model, threshold, cfg, progress=lambda _: None)
    return PoseEstimator(model, det, threshold, CORRECTOR)


def _keypoint_rms_mm(estimator, clouds):
    model = estimator.model
    kp = torch.as_tensor(model.keypoints, dtype=torch.float32)
    truth = torch.stack(
        [
            transform(
                kp,
                torch.as_tensor(c.true_pose[:3, :3], dtype=torch.float32),
                torch.as_tensor(c.true_pose[:3, 3], dtype=torch.float32),
            )
            for c in clouds
        ]
    )
    with torch.no_grad():
        pred = estimator.detector(torch.stack([torch.from_numpy(c.points) for c in clouds]))
    return float(symmetric_keypoint_loss(pred, truth, torch.as_tensor(model.symmetries))) ** 0.5 * 1000


def test_scene_clouds_are_the_models_instances_with_a_frames_sides_joined(rendered, mission):
    images = ImageSet(rendered)
    pipeline = PartPipeline({}, max_points=512, keep_border_below=400)
    joints = scene_clouds(images, "corner_joint", pipeline)
    expected = sum(
        int((images[i].labels == images.classes.index("corner_joint") + 1).sum()) for i in range(len(images))
    )
    assert 0 < len(joints) <= expected
    size = models_for_mission(mission)["corner_joint"].diameter
    for c in joints:
        assert c.points.shape[1] == 3 and len(c.points) <= 512
        # Every cloud is of the part whose pose it carries: its points lie around that pose.
        assert np.linalg.norm(np.median(c.points, axis=0) - c.true_pose[:3, 3]) < size
    frames = scene_clouds(images, "cross_frame", pipeline)
    sides = sum(
        int((images[i].labels == images.classes.index("cross_frame") + 1).sum()) for i in range(len(images))
    )
    parts = {c.source for c in frames}
    assert len(parts) == len(frames) and 0 < len(frames) < sides
    assert all(not c.source.split(":")[1].endswith(("side_0", "side_1", "side_2", "side_3")) for c in frames)
    # A tube is posed with the model of its kind: no diagonal among the verticals' clouds.
    verticals = scene_clouds(images, "strut_tube/vertical", pipeline)
    assert all("diagonal" not in c.source for c in verticals)
    assert len(scene_clouds(images, "corner_joint", pipeline, limit=2)) == 2


def test_certified_poses_teach_a_weak_detector_the_truth_it_never_sees(mission):
    torch.manual_seed(0)
    estimator = _weak_estimator(mission, "end_fitting")
    rng = np.random.default_rng(5)
    train, val = _views(estimator.model, 256, rng), _views(estimator.model, 40, rng)
    before = _keypoint_rms_mm(estimator, val)
    labelled = evaluate(estimator, train, label_batch=64)
    samples = [(c.points, e.keypoints) for c, e in zip(train, labelled.estimates, strict=True) if e.certified]
    assert 0 < len(samples) < len(train)  # some views are not certified: they give no label
    optimiser = torch.optim.Adam(estimator.detector.parameters(), lr=1e-3)
    generator = torch.Generator().manual_seed(0)
    losses = [
        train_epoch(estimator.detector, estimator.model, samples, optimiser, 32, generator) for _ in range(3)
    ]
    assert losses[-1] < losses[0]
    # No pose label was read, yet the detector alone is now nearer the true keypoints.
    assert _keypoint_rms_mm(estimator, val) < 0.9 * before


def test_the_best_validation_epoch_is_kept_when_training_makes_it_worse(mission):
    torch.manual_seed(0)
    estimator = _weak_estimator(mission, "end_fitting")
    start = copy.deepcopy(estimator.detector.state_dict())
    rng = np.random.default_rng(6)
    train, val = _views(estimator.model, 64, rng), _views(estimator.model, 24, rng)
    cfg = SelfSupervisedConfig(epochs=2, patience=5, lr=0.05, target=1.01)  # a rate that wrecks it
    lines = []
    det, history, reason = train_self_supervised(estimator, train, val, cfg, lines.append)
    assert [h["epoch"] for h in history] == [0, 1, 2]
    assert max(h["val_certified"] for h in history[1:]) < history[0]["val_certified"]
    assert all(torch.equal(v, start[k]) for k, v in det.state_dict().items())
    assert reason == "2 epochs run"
    assert lines[0].startswith("epoch 0/2: validation certified") and "training clouds certified" in lines[1]
    figures = {"train_certified", "val_certified", "val_non_degenerate", "val_add_s_ok", "train_loss"}
    assert figures <= set(history[1])


def test_training_stops_at_the_target_and_when_learning_stops(mission):
    torch.manual_seed(0)
    estimator = _weak_estimator(mission, "end_fitting")
    rng = np.random.default_rng(7)
    train, val = _views(estimator.model, 32, rng), _views(estimator.model, 16, rng)
    _, history, reason = train_self_supervised(
        estimator, train, val, SelfSupervisedConfig(target=0.0), lambda _: None
    )
    assert len(history) == 1 and reason.startswith("the starting detector certifies")
    _, history, reason = train_self_supervised(
        estimator, train, val, SelfSupervisedConfig(epochs=5, patience=1, lr=0.0, target=1.01), lambda _: None
    )
    assert len(history) == 2 and reason == "epoch 1: no better validation certified fraction for 1 epochs"
    with pytest.raises(ValueError, match="need training and validation clouds"):
        train_self_supervised(estimator, [], val, SelfSupervisedConfig(), lambda _: None)


def test_command_writes_weights_the_node_loads_with_a_plot(rendered, mission, tmp_path, capsys):
    out, plot = tmp_path / "corner_joint.pt", tmp_path / "curves.png"
    rc = main(
        [
            "--model",
            "corner_joint",
            "--images",
            str(rendered),
            "--val",
            str(rendered),
            "--epochs",
            "1",
            "--target",
            "1.01",
            "--out",
            str(out),
            "--plot",
            str(plot),
            "--mission",
            MISSION,
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "training clouds" in text and "epoch 0/1" in text and "stopped: " in text
    manifest = read_manifest(out)
    training = manifest["extra"]["training"]
    assert training["stage"] == "self_supervised" and training["stopped"]
    assert training["started_from"]["path"].endswith("models/vision/corner_joint.pt")
    assert manifest["extra"]["history"][0]["epoch"] == 0
    model = models_for_mission(mission)["corner_joint"]
    assert load_detector(out, model, manifest["settings"]["width"]).num_keypoints == 8
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_command_refuses_bad_input_with_the_reason(rendered, tmp_path, capsys):
    args = ["--val", str(rendered), "--out", str(tmp_path / "x.pt"), "--mission", MISSION]
    assert main(["--model", "nope", "--images", str(rendered), *args]) == 2
    assert "detectors" in (err := capsys.readouterr().err) and "no 'nope'" in err
    assert main(["--model", "rivet", "--images", str(tmp_path / "missing"), *args]) == 2
    assert f"{tmp_path / 'missing' / 'index.json'}: no such file" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    write_index(empty, ImageSet(rendered).classes, 640, 480, [], {})
    assert main(["--model", "rivet", "--images", str(empty), *args]) == 2
    assert "no usable cloud of rivet in the training images" in capsys.readouterr().err
    assert not (tmp_path / "x.pt").exists()
