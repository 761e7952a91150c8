"""Box-branch masks trimmed of the pixels the semantic head holds to be a thin part."""

from __future__ import annotations

import pytest
import torch

from tlt_vision.segmentation.semantic_trim import SemanticTrim, semantic_cores, trim_by_semantic

TUBE, FITTING, FRAME, JOINT = 1, 2, 3, 4


def _result() -> dict[str, torch.Tensor]:
    """An end fitting whose mask takes in two columns of tube, a corner joint over the same
    columns, and a second end fitting lying wholly on frame side."""
    masks = torch.zeros((3, 8, 8), dtype=torch.bool)
    masks[0, 2:6, 2:6] = True  # fitting, its columns 4 and 5 on the tube
    masks[1, 2:6, 2:6] = True  # corner joint, same pixels
    masks[2, 0:2, 0:2] = True  # fitting on a frame side
    probs = torch.zeros((5, 8, 8))
    probs[TUBE, :, 4] = 0.9
    probs[TUBE, :, 5] = 0.3  # not above 0.3: kept
    probs[FRAME, 0:2, 0:2] = 0.8
    return {
        "boxes": torch.tensor([[2.0, 2, 6, 6], [2, 2, 6, 6], [0, 0, 2, 2]]),
        "labels": torch.tensor([FITTING, JOINT, FITTING]),
        "scores": torch.tensor([0.9, 0.8, 0.7]),
        "masks": masks,
        "semantic_probs": probs,
    }


def test_the_named_class_loses_the_thin_parts_pixels_and_an_emptied_instance_is_dropped():
    result = _result()
    out = trim_by_semantic(result, (FITTING,), (TUBE, FRAME), 0.3)
    assert out["labels"].tolist() == [FITTING, JOINT] and out["scores"].tolist() == pytest.approx([0.9, 0.8])
    fitting, joint = out["masks"]
    assert fitting[2:6, 2:4].all() and not fitting[:, 4].any()  # the tube's column taken
    assert fitting[2:6, 5].all()  # a probability at the threshold is not above it
    assert int(fitting.sum()) == 12
    assert torch.equal(joint, result["masks"][1])  # a class not named is left as it was
    assert out["semantic_probs"] is result["semantic_probs"]
    assert int(result["masks"][0].sum()) == 16  # the input is not changed


def test_nothing_to_trim_gives_the_same_result():
    result = _result()
    assert trim_by_semantic(result, (), (TUBE, FRAME), 0.3) is result
    assert trim_by_semantic(result, (5,), (TUBE, FRAME), 0.3) is result  # no rivet detected
    without = {k: v for k, v in result.items() if k != "semantic_probs"}
    assert trim_by_semantic(without, (FITTING,), (TUBE, FRAME), 0.3) is without


def test_a_cored_class_keeps_its_mask_and_gets_it_trimmed_beside_it():
    result = _result()
    out = semantic_cores(result, (JOINT,), (TUBE, FRAME), 0.3)
    assert torch.equal(out["masks"], result["masks"]) and out["labels"].tolist() == [FITTING, JOINT, FITTING]
    fitting, joint, side = out["core_masks"]
    assert torch.equal(fitting, result["masks"][0]) and torch.equal(side, result["masks"][2])  # not cored
    assert not joint[:, 4].any() and joint[2:6, 5].all() and int(joint.sum()) == 12
    assert "core_masks" not in result  # the input is not changed
    assert semantic_cores(result, (), (TUBE, FRAME), 0.3) is result
    without = {k: v for k, v in result.items() if k != "semantic_probs"}
    assert semantic_cores(without, (JOINT,), (TUBE, FRAME), 0.3) is without


def test_trim_names_resolve_to_the_models_labels():
    classes = ("strut_tube", "end_fitting", "cross_frame", "corner_joint", "rivet")
    assert SemanticTrim(("rivet", "end_fitting"), 0.3).labels(classes) == (5, 2)
    assert SemanticTrim(("end_fitting",), 0.3, ("corner_joint",)).core_labels(classes) == (4,)
