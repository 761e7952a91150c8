import numpy as np
import pytest
import torch

from tlt_vision.segmentation.backbone import FPN, Backbone
from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.matching import BACKGROUND, IGNORE, match, sample
from tlt_vision.segmentation.model import MaskRCNN, predict, train_step
from tlt_vision.segmentation.roi_heads import assign_levels, paste_masks
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
)


def test_backbone_and_fpn_shapes():
    feats = Backbone(TINY.backbone_channels)(torch.zeros(2, 3, 64, 96))
    assert [tuple(f.shape[-2:]) for f in feats] == [(16, 24), (8, 12), (4, 6), (2, 3)]
    pyr = FPN(TINY.backbone_channels, 16)(feats)
    assert [tuple(p.shape) for p in pyr] == [(2, 16, 16, 24), (2, 16, 8, 12), (2, 16, 4, 6), (2, 16, 2, 3)]


def test_match_hand_checked():
    gt = torch.tensor([[0.0, 0.0, 10.0, 10.0]])
    boxes = torch.tensor(
        [[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 5.0], [0.0, 0.0, 10.0, 1.0], [50.0, 50.0, 60.0, 60.0]]
    )
    # IoUs 1, 0.5, 0.1, 0 with fg 0.7, bg 0.3.
    assert match(gt, boxes, 0.7, 0.3, False).tolist() == [0, IGNORE, BACKGROUND, BACKGROUND]
    # Without its exact box, the ground truth keeps its best (low quality) match.
    assert match(gt, boxes[1:], 0.7, 0.3, True).tolist() == [0, BACKGROUND, BACKGROUND]
    assert match(torch.zeros(0, 4), boxes, 0.7, 0.3, True).tolist() == [BACKGROUND] * 4
    pos, neg = sample(torch.tensor([0, 0, 0, BACKGROUND, BACKGROUND, IGNORE]), 4, 0.5)
    assert len(pos) == 2 and len(neg) == 2
    assert set(neg.tolist()) == {3, 4}


def test_level_assignment_and_mask_paste():
    boxes = torch.tensor([[0.0, 0.0, 112.0, 112.0], [0.0, 0.0, 56.0, 56.0], [0.0, 0.0, 8.0, 8.0]])
    assert assign_levels(boxes, 4).tolist() == [2, 1, 0]
    probs = torch.ones(1, 28, 28)
    pasted = paste_masks(probs, torch.tensor([[2.0, 3.0, 6.0, 5.0]]), (8, 8)) >= 0.5
    expected = torch.zeros(8, 8, dtype=torch.bool)
    expected[3:5, 2:6] = True
    assert torch.equal(pasted[0], expected)


def test_pasting_in_the_box_gives_what_sampling_the_whole_image_gives():
    # Masks pasted only over their boxes (and a margin) lose nothing: the bilinear samples
    # beyond it are zero, including boxes at the image's edges, sub-pixel and fractional ones.
    torch.manual_seed(0)
    h, w = 40, 52
    boxes = torch.tensor(
        [
            [3.2, 4.7, 20.1, 11.3],
            [0.0, 0.0, 52.0, 40.0],
            [40.5, 30.2, 52.0, 40.0],
            [10.2, 10.3, 10.8, 10.9],
            [-2.0, 35.0, 5.0, 41.0],
        ]
    )
    probs = torch.rand(len(boxes), 14, 14)
    ys, xs = torch.arange(h) + 0.5, torch.arange(w) + 0.5
    gx = (xs[None] - boxes[:, :1]) / (boxes[:, 2:3] - boxes[:, :1]) * 2 - 1
    gy = (ys[None] - boxes[:, 1:2]) / (boxes[:, 3:4] - boxes[:, 1:2]) * 2 - 1
    grid = torch.stack([gx[:, None, :].expand(-1, h, -1), gy[:, :, None].expand(-1, -1, w)], dim=-1)
    whole = torch.nn.functional.grid_sample(probs[:, None], grid, align_corners=False)[:, 0]
    pasted = paste_masks(probs, boxes, (h, w))
    assert pasted.shape == (len(boxes), h, w)
    assert torch.allclose(pasted, whole, atol=1e-6)
    assert float(pasted[3].sum()) > 0  # the sub-pixel box still leaves its trace
    assert paste_masks(probs[:0], boxes[:0], (h, w)).shape == (0, h, w)


def test_training_losses_backward_and_a_few_steps_reduce_the_loss():
    torch.manual_seed(0)
    model = MaskRCNN(TINY)
    images, targets = toy_batch(np.random.default_rng(0), 2, size=(32, 32))
    model.train()
    losses = model(images, targets)
    assert set(losses) == {"rpn_objectness", "rpn_box", "roi_cls", "roi_box", "roi_mask"}
    assert all(torch.isfinite(v) for v in losses.values())
    sum(losses.values()).backward()
    assert model.roi_heads.mask_head.logits.weight.grad is not None
    assert model.backbone.stem[0].weight.grad.abs().sum() > 0
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    totals = [train_step(model, opt, images, targets)["total"] for _ in range(8)]
    assert np.mean(totals[-2:]) < 0.8 * np.mean(totals[:2])  # about 0.55-0.65 over seeds


def test_eval_outputs():
    torch.manual_seed(0)
    model = MaskRCNN(TINY)
    out = predict(model, torch.rand(2, 3, 40, 56))
    assert len(out) == 2
    for det in out:
        d = len(det["boxes"])
        assert det["boxes"].shape == (d, 4) and det["scores"].shape == (d,)
        assert det["masks"].shape == (d, 40, 56) and det["masks"].dtype == torch.bool
        assert d <= TINY.detections_per_image
        assert ((det["labels"] >= 1) & (det["labels"] <= 5)).all()
        assert (det["boxes"][:, 2] <= 56).all() and (det["boxes"][:, 3] <= 40).all()


def test_inference_settings_change_what_the_model_does_not_its_weights():
    """Proposals scored per image (rpn_post_nms_top_n_test) and detections kept are the model's and
    its parts' at once; a setting of what was trained is refused by name."""
    torch.manual_seed(0)
    model = MaskRCNN(TINY).eval()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    image = torch.rand(1, 3, 40, 56)

    def proposals() -> int:
        with torch.no_grad():
            return len(model.rpn(model.features(image)[1], (40, 56))[0][0])

    assert proposals() == TINY.rpn_post_nms_top_n_test
    model.set_inference(rpn_post_nms_top_n_test=7, detections_per_image=3, score_threshold=0.0)
    assert proposals() == 7 and model.rpn.cfg is model.cfg and model.roi_heads.cfg is model.cfg
    assert len(predict(model, image)[0]["boxes"]) == 3
    assert all(torch.equal(v, before[k]) for k, v in model.state_dict().items())
    with pytest.raises(ValueError, match="not inference settings: fpn_channels"):
        model.set_inference(fpn_channels=8)


def test_bad_input_rejected():
    model = MaskRCNN(TINY)
    with pytest.raises(ValueError, match="expected images"):
        model(torch.zeros(3, 32, 32))
    model.train()
    with pytest.raises(ValueError, match="target"):
        model(torch.zeros(1, 3, 32, 32))


def test_config_round_trip():
    assert MaskRCNNConfig.from_dict(TINY.to_dict()) == TINY
    with pytest.raises(ValueError, match="unknown"):
        MaskRCNNConfig.from_dict({"nope": 1})


def test_images_without_objects_train_and_predict_nothing():
    import dataclasses

    torch.manual_seed(0)
    model = MaskRCNN(TINY)
    empty = {
        "boxes": torch.zeros(0, 4),
        "labels": torch.zeros(0, dtype=torch.long),
        "masks": torch.zeros(0, 32, 32, dtype=torch.bool),
    }
    out = train_step(
        model, torch.optim.SGD(model.parameters(), lr=1e-3), torch.rand(2, 3, 32, 32), [empty, empty]
    )
    assert out["rpn_box"] == 0.0 and out["roi_mask"] == 0.0 and np.isfinite(out["total"])
    strict = MaskRCNN(dataclasses.replace(TINY, score_threshold=0.99))
    for det in predict(strict, torch.rand(1, 3, 32, 32)):
        assert det["boxes"].shape == (0, 4) and det["masks"].shape == (0, 32, 32)
