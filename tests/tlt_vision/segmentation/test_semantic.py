import dataclasses

import numpy as np
import pytest
import torch

from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.inference import detect_rgb
from tlt_vision.segmentation.model import MaskRCNN, predict
from tlt_vision.segmentation.semantic import instances_from_semantic, label_map, pixel_classes, semantic_loss
from tlt_vision.segmentation.synthetic import toy_batch

TINY = MaskRCNNConfig(
    backbone_channels=(8, 8, 16, 16),
    fpn_channels=16,
    representation=32,
    mask_convs=1,
    rpn_pre_nms_top_n=100,
    rpn_post_nms_top_n_train=50,
    rpn_post_nms_top_n_test=30,
    rpn_batch_per_image=64,
    roi_batch_per_image=32,
    semantic_channels=16,
    semantic_classes=("strut_tube", "cross_frame"),
)


def _probs(label_image: np.ndarray, classes: int = 6, confidence: float = 0.9) -> torch.Tensor:
    """Class probabilities (C, H, W) that put ``confidence`` on each pixel's label."""
    lab = torch.from_numpy(label_image).long()
    p = torch.full((classes, *lab.shape), (1 - confidence) / (classes - 1))
    p.scatter_(0, lab[None], confidence)
    return p


def test_regions_of_a_class_are_its_instances():
    image = np.zeros((20, 30), dtype=np.int64)
    image[2:4, 1:25] = 1  # a tube lying level
    image[8:10, 1:25] = 1  # a second one, a gap of four rows below
    image[12:18, 12] = 1  # touching nothing: a third
    image[14, 20:22] = 1  # two pixels: noise
    image[15:19, 25:29] = 4  # a corner joint: not a semantic class here
    image[2:4, 25:28] = 2  # an end fitting closing the first tube
    found = instances_from_semantic(_probs(image), labels=(1, 3), min_area=4)
    assert found["labels"].tolist() == [1, 1, 1]
    assert found["boxes"].tolist() == [[1, 2, 25, 4], [1, 8, 25, 10], [12, 12, 13, 18]]
    expected = np.zeros((3, 20, 30), dtype=bool)
    expected[0, 2:4, 1:25] = expected[1, 8:10, 1:25] = expected[2, 12:18, 12] = True
    assert np.array_equal(found["masks"].numpy(), expected)
    assert torch.allclose(found["scores"], torch.full((3,), 0.9))


def test_a_diagonal_line_is_one_region_and_an_empty_map_gives_nothing():
    image = np.zeros((16, 16), dtype=np.int64)
    idx = np.arange(2, 14)
    image[idx, idx] = 3  # pixels touching at their corners only
    found = instances_from_semantic(_probs(image), labels=(1, 3), min_area=4)
    assert found["labels"].tolist() == [3] and int(found["masks"].sum()) == 12
    none = instances_from_semantic(_probs(np.zeros((16, 16), dtype=np.int64)), labels=(1, 3), min_area=4)
    assert none["boxes"].shape == (0, 4) and none["masks"].shape == (0, 16, 16)


def test_a_background_weight_below_one_keeps_a_tube_whole_through_its_doubtful_pixels():
    """A tube whose middle the head doubts (background 0.55, tube 0.45) is two regions when each
    pixel takes its most probable class, one when the background counts half; a pixel the head
    is sure of as background (0.9) stays so, and a region of doubtful pixels alone is no part."""
    image = np.zeros((5, 21), dtype=np.int64)
    image[2, 1:20] = 1
    probs = _probs(image)
    probs[:, 2, 10] = torch.tensor([0.55, 0.45, 0, 0, 0, 0])
    probs[:, 0, 0] = torch.tensor([0.9, 0.08, 0, 0.02, 0, 0])
    halves = instances_from_semantic(probs, labels=(1, 3), min_area=4)
    assert halves["boxes"].tolist() == [[1, 2, 10, 3], [11, 2, 20, 3]]
    whole = instances_from_semantic(probs, labels=(1, 3), min_area=4, background_weight=0.5)
    assert whole["boxes"].tolist() == [[1, 2, 20, 3]]
    probs[:, 4, 2:12] = torch.tensor([0.6, 0.4, 0, 0, 0, 0])[:, None]  # a streak of doubt alone
    read = pixel_classes(probs, 0.5)
    assert read[4, 2:12].eq(1).all() and int(read[0, 0]) == 0
    assert torch.equal(read, torch.where(read == 0, 0, 1))
    again = instances_from_semantic(probs, labels=(1, 3), min_area=4, background_weight=0.5)
    assert again["boxes"].tolist() == [[1, 2, 20, 3]]
    assert torch.equal(pixel_classes(probs), probs.max(dim=0).indices)


def test_with_the_vote_a_part_whose_class_wavers_is_one_region_of_its_likelier_class():
    """A bar whose pixels the head calls tube and frame side by turns (0.55 against 0.35, the tube
    ahead on most of them) is seven pieces of both classes class by class, one tube with the vote,
    scored by its tube probability; a pixel of a box-branch class still parts it."""
    image = np.zeros((5, 24), dtype=np.int64)
    image[2, 1:22] = 1
    image[2, 5:8] = image[2, 12:14] = image[2, 17:19] = 3
    probs = _probs(image, confidence=0.5)
    probs[:, 2, 1:22] = torch.tensor([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])[:, None]
    probs[1, 2, 1:22] = torch.where(torch.from_numpy(image[2, 1:22] == 1), 0.55, 0.35)
    probs[3, 2, 1:22] = 0.9 - probs[1, 2, 1:22]
    apart = instances_from_semantic(probs, labels=(1, 3), min_area=1)
    assert sorted(apart["labels"].tolist()) == [1, 1, 1, 1, 3, 3, 3]
    whole = instances_from_semantic(probs, labels=(1, 3), min_area=1, vote=True)
    assert whole["labels"].tolist() == [1] and whole["boxes"].tolist() == [[1, 2, 22, 3]]
    assert float(whole["scores"][0]) == pytest.approx((14 * 0.55 + 7 * 0.35) / 21)
    image[2, 10] = 2  # an end fitting between: two parts
    probs[:, 2, 10] = torch.tensor([0.0, 0.1, 0.9, 0.0, 0.0, 0.0])
    two = instances_from_semantic(probs, labels=(1, 3), min_area=1, vote=True)
    assert two["boxes"].tolist() == [[1, 2, 10, 3], [11, 2, 22, 3]]
    # Without a pixel sure of being a thin part (tube and frame side together), no part at all.
    probs[1, 2, 1:22], probs[3, 2, 1:22] = 0.2, 0.2
    assert len(instances_from_semantic(probs, labels=(1, 3), min_area=1, vote=True)["labels"]) == 0


def test_with_the_background_weighted_a_pixel_takes_the_likelier_thin_class():
    probs = torch.tensor([0.5, 0.2, 0.0, 0.3, 0.0, 0.0])[:, None, None]
    assert int(pixel_classes(probs, 0.5)) == 3
    assert int(pixel_classes(probs, 1.0)) == 0


def test_label_map_and_loss_weighting():
    masks = torch.zeros(2, 4, 4, dtype=torch.bool)
    masks[0, 0, :] = True
    masks[1, 3, 1:3] = True
    target = {"masks": masks, "labels": torch.tensor([1, 4])}
    expected = torch.zeros(4, 4, dtype=torch.long)
    expected[0, :] = 1
    expected[3, 1:3] = 4
    assert torch.equal(label_map(target, (4, 4)), expected)
    assert torch.equal(label_map(target, (4, 4), gap=1), expected)  # nothing touches its own class


def test_label_map_cuts_touching_instances_of_a_class_apart():
    masks = torch.zeros(3, 6, 8, dtype=torch.bool)
    masks[0, 0:2, :] = True  # two tubes racked one on the other: rows 0-1 and 2-3
    masks[1, 2:4, :] = True
    masks[2, 4:6, 0:3] = True  # an end fitting below the second tube: another class
    target = {"masks": masks, "labels": torch.tensor([1, 1, 2])}
    expected = torch.zeros(6, 8, dtype=torch.long)
    expected[0, :] = 1  # row 1 and row 2 are within a pixel of the other tube
    expected[3, :] = 1
    expected[4:6, 0:3] = 2
    assert torch.equal(label_map(target, (6, 8), gap=1), expected)
    # Two pixels: every row of these two-row tubes is near the other, and none is left.
    assert torch.equal(label_map(target, (6, 8), gap=2)[0:4], torch.zeros(4, 8, dtype=torch.long))
    # The regions of the cut map are the two tubes.
    probs = torch.nn.functional.one_hot(label_map(target, (6, 8), gap=1), 6).permute(2, 0, 1).float()
    found = instances_from_semantic(probs, labels=(1,), min_area=4)
    assert found["boxes"].tolist() == [[0, 0, 8, 1], [0, 3, 8, 4]]
    # Stride-2 logits that say "background" everywhere: the object pixels cost more when weighted.
    logits = torch.zeros(1, 6, 2, 2)
    logits[:, 0] = 2.0
    plain = semantic_loss(logits, [target], fg_weight=1.0)
    weighted = semantic_loss(logits, [target], fg_weight=3.0)
    assert weighted > plain > 0


def test_semantic_classes_must_be_classes():
    with pytest.raises(ValueError, match="semantic_classes"):
        MaskRCNNConfig(semantic_classes=("strut",))
    with pytest.raises(ValueError, match="semantic_background_weight 0"):
        MaskRCNNConfig(semantic_background_weight=0.0)
    assert TINY.semantic_labels == (1, 3)
    assert MaskRCNNConfig.from_dict(TINY.to_dict()) == TINY


def test_model_trains_its_semantic_head_and_finds_thin_parts_with_it():
    torch.manual_seed(0)
    model = MaskRCNN(TINY)
    images, targets = toy_batch(np.random.default_rng(3), 4, size=(48, 48))
    model.train()
    losses = model(images, targets)
    assert "semantic" in losses
    losses["semantic"].backward()
    assert model.semantic.logits.weight.grad.abs().sum() > 0
    assert model.backbone.stem[0].weight.grad.abs().sum() > 0
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    semantic = []
    for _ in range(40):  # the semantic loss alone: the box branch is another test's
        loss = model(images, targets)["semantic"]
        opt.zero_grad()
        loss.backward()
        opt.step()
        semantic.append(float(loss.detach()))
    assert semantic[-1] < 0.5 * semantic[0]
    tubes = [t["masks"][t["labels"] == 1] for t in targets]
    found = 0
    for det, truth in zip(predict(model, images), tubes, strict=True):
        # The head's class probabilities come with the detections (the vision node scores the
        # pieces it cuts the regions into by them): each region's score is its class's mean there.
        probs = det["semantic_probs"]
        assert probs.shape == (TINY.num_classes, 48, 48) and torch.allclose(probs.sum(0), torch.ones(48, 48))
        for label, score, mask in zip(det["labels"], det["scores"], det["masks"], strict=True):
            if int(label) in TINY.semantic_labels:
                assert float(score) == pytest.approx(float(probs[label][mask].mean()), rel=1e-5)
        sem = det["masks"][det["labels"] == 1]
        for gt in truth:
            inter = (sem & gt).flatten(1).sum(1).float()
            union = (sem | gt).flatten(1).sum(1).float()
            found += int(len(sem) > 0 and (inter / union).max() >= 0.5)
    assert found >= 0.75 * sum(len(t) for t in tubes)
    rgb = (images[0].permute(1, 2, 0).numpy() * 255).astype(np.uint8)
    assert detect_rgb(model, rgb, 24)["semantic_probs"].shape == (TINY.num_classes, 48, 48)


def test_box_branch_detections_of_semantic_classes_are_dropped():
    torch.manual_seed(0)
    lax = dataclasses.replace(TINY, score_threshold=0.0, semantic_min_area=10**6)
    for det in predict(MaskRCNN(lax), torch.rand(2, 3, 40, 56)):
        assert len(det["labels"]) > 0
        assert not ((det["labels"] == 1) | (det["labels"] == 3)).any()
