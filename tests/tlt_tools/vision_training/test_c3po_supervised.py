import pytest
from tlt_tools.vision_training.c3po_supervised import main

from tlt_vision.cad.models import build_models
from tlt_vision.pose.detector_weights import load_detector
from tlt_vision.weights import WeightsError, read_manifest


def test_command_trains_reports_progress_and_writes_loadable_weights(tmp_path, capsys):
    out = tmp_path / "rivet.pt"
    rc = main(
        [
            "--model", "rivet", "--out", str(out), "--train-samples", "32", "--val-samples", "4",
            "--epochs", "3", "--points", "24", "--width", "8", "--certify-samples", "1", "--batch", "16",
        ]
    )  # fmt: skip
    assert rc == 0
    text = capsys.readouterr().out
    assert "epoch 1/3" in text and "epoch 3/3" in text and "certified" in text
    manifest = read_manifest(out)
    history = manifest["extra"]["history"]
    assert len(history) == 3
    assert history[-1]["train_loss"] < history[0]["train_loss"]
    rivet = build_models(0.75, {"vertical": 0.75})["rivet"]
    det = load_detector(out, rivet, width=8)
    assert det.num_keypoints == 2
    with pytest.raises(WeightsError, match="expected"):
        load_detector(out, build_models(0.75, {"vertical": 0.75})["end_fitting"], width=8)


def test_command_rejects_unknown_model(tmp_path, capsys):
    assert main(["--model", "nope", "--out", str(tmp_path / "x.pt")]) == 2
    assert "unknown model 'nope'" in capsys.readouterr().err
    assert main(["--model", "rivet", "--mission", str(tmp_path / "none.yaml"), "--out", "x.pt"]) == 2
