"""Exclusive box-branch masks: a pixel two masks of one class share stays in the more probable."""

import torch

from tlt_vision.segmentation.overlap import resolve_overlaps

FITTING, RIVET = 2, 5


def result(masks: list[list[list[int]]], probs: list[list[list[float]]], labels: list[int]) -> dict:
    return {
        "boxes": torch.zeros((len(labels), 4)),
        "scores": torch.ones(len(labels)),
        "labels": torch.tensor(labels),
        "masks": torch.tensor(masks, dtype=torch.bool),
        "mask_probs": torch.tensor(probs),
    }


def test_each_shared_pixel_stays_in_the_mask_more_probable_there():
    # Two fittings side by side, each mask taking in the other's nearest column.
    r = result(
        [[[1, 1, 1, 0]], [[0, 1, 1, 1]]],
        [[[0.9, 0.8, 0.6, 0.1]], [[0.1, 0.7, 0.9, 0.9]]],
        [FITTING, FITTING],
    )
    out = resolve_overlaps(r, [FITTING], duplicate=0.8)
    assert out["masks"].int().tolist() == [[[1, 1, 0, 0]], [[0, 0, 1, 1]]]
    assert r["masks"].int().tolist() == [[[1, 1, 1, 0]], [[0, 1, 1, 1]]]  # the model's, untouched


def test_duplicates_other_classes_and_results_without_probabilities_are_left_alone():
    # Two detections of one fitting: they share 3 of the smaller's 3 pixels.
    dup = result([[[1, 1, 1, 0]], [[1, 1, 1, 1]]], [[[0.9, 0.9, 0.9, 0.1]], [[0.6, 0.6, 0.6, 0.6]]],
                 [FITTING, FITTING])  # fmt: skip
    assert resolve_overlaps(dup, [FITTING], duplicate=0.6) is dup
    # A rivet and a fitting may share pixels, and rivets are not asked for here.
    mixed = result([[[1, 1, 0]], [[0, 1, 1]]], [[[0.9, 0.2, 0.0]], [[0.0, 0.9, 0.9]]], [FITTING, RIVET])
    assert resolve_overlaps(mixed, [FITTING, RIVET], duplicate=0.6) is mixed
    rivets = result([[[1, 1, 0]], [[0, 1, 1]]], [[[0.9, 0.2, 0.0]], [[0.0, 0.9, 0.9]]], [RIVET, RIVET])
    assert resolve_overlaps(rivets, [FITTING], duplicate=0.6) is rivets
    del rivets["mask_probs"]
    assert resolve_overlaps(rivets, [RIVET], duplicate=0.6) is rivets
