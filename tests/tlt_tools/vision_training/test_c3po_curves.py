from pathlib import Path

from PIL import Image
from tlt_tools.vision_training.c3po_curves import histories, main

MODELS = Path(__file__).resolve().parents[3] / "models" / "vision"


def test_the_shipped_detectors_curves_are_read_from_their_manifests_and_drawn(tmp_path, capsys):
    curves = histories([MODELS / "rivet.pt", MODELS / "corner_joint.pt"])
    assert [len(h) for h in curves.values()] == [6, 20]  # epochs, as their cards say
    assert all(0.0 <= h["val_certified"] <= 1.0 for h in curves["corner_joint"])
    out = tmp_path / "curves.png"
    assert main([str(MODELS / "rivet.pt"), str(MODELS / "corner_joint.pt"), "--out", str(out)]) == 0
    assert Image.open(out).size[0] > 500


def test_weights_without_a_training_history_are_refused_naming_the_file(tmp_path, capsys):
    assert main([str(MODELS / "mask_rcnn.pt"), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "mask_rcnn.pt" in err and "no training history" in err
    assert not (tmp_path / "x.png").exists()
    assert main([str(tmp_path / "missing.pt"), "--out", str(tmp_path / "x.png")]) == 2
    assert "missing.pt" in capsys.readouterr().err
