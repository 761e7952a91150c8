import json

import pytest
import torch

from tlt_vision.pose.detector import KeypointDetector
from tlt_vision.weights import WeightsError, load_weights, manifest_path, read_manifest, save_weights


def _saved(tmp_path, width=8):
    torch.manual_seed(0)
    det = KeypointDetector(4, 0.3, width=width)
    path = tmp_path / "tube.pt"
    save_weights(det, path, "c3po_detector", "0.1", ["strut_tube"], {"width": width}, {"val_loss": 0.1})
    return det, path


def test_round_trip(tmp_path):
    det, path = _saved(tmp_path)
    fresh = KeypointDetector(4, 0.3, width=8)
    manifest = load_weights(fresh, path, "c3po_detector", ["strut_tube"])
    assert manifest["extra"] == {"val_loss": 0.1} and manifest["version"] == "0.1"
    for a, b in zip(det.state_dict().values(), fresh.state_dict().values(), strict=True):
        assert torch.equal(a, b)


def test_missing_files_named(tmp_path):
    with pytest.raises(WeightsError, match=r"nope\.pt: weights file not found"):
        load_weights(KeypointDetector(4, 0.3, width=8), tmp_path / "nope.pt", "c3po_detector")
    _, path = _saved(tmp_path)
    manifest_path(path).unlink()
    with pytest.raises(WeightsError, match=r"tube\.json: manifest not found"):
        read_manifest(path)


def test_shape_mismatch_names_tensor_and_expected_shape(tmp_path):
    _, path = _saved(tmp_path, width=8)
    with pytest.raises(WeightsError) as err:
        load_weights(KeypointDetector(4, 0.3, width=16), path, "c3po_detector")
    msg = str(err.value)
    assert str(path) in msg
    assert "tensor point_mlp.0.weight has shape (8, 3, 1), expected (16, 3, 1)" in msg


def test_kind_classes_and_tampering_refused(tmp_path):
    _, path = _saved(tmp_path)
    det = KeypointDetector(4, 0.3, width=8)
    with pytest.raises(WeightsError, match="expected 'mask_rcnn'"):
        load_weights(det, path, "mask_rcnn")
    with pytest.raises(WeightsError, match="classes"):
        load_weights(det, path, "c3po_detector", ["rivet"])
    with path.open("ab") as f:
        f.write(b"junk")
    with pytest.raises(WeightsError, match="SHA-256"):
        load_weights(det, path, "c3po_detector")
    m = json.loads(manifest_path(path).read_text())
    del m["shapes"]
    manifest_path(path).write_text(json.dumps(m))
    with pytest.raises(WeightsError, match="lacks 'shapes'"):
        read_manifest(path)
