import numpy as np
import torch

from tlt_vision.cad.models import build_models
from tlt_vision.cad.views import random_rotation, synthetic_view
from tlt_vision.ops.registration import transform
from tlt_vision.pose.detector import KeypointDetector, symmetric_keypoint_loss


def test_shapes_and_padding_mask():
    torch.manual_seed(0)
    det = KeypointDetector(num_keypoints=4, scale=0.3, width=8)
    pts = torch.randn(2, 50, 3)
    assert det(pts).shape == (2, 4, 3)
    padded = torch.cat([pts, torch.full((2, 20, 3), 99.0)], dim=1)
    mask = torch.zeros(2, 70, dtype=torch.bool)
    mask[:, :50] = True
    assert torch.allclose(det(padded, mask), det(pts), atol=1e-5)


def test_translation_moves_the_keypoints():
    torch.manual_seed(0)
    det = KeypointDetector(3, 0.1, width=8)
    pts = torch.randn(1, 30, 3) * 0.1
    shift = torch.tensor([0.5, -0.2, 1.0])
    assert torch.allclose(det(pts + shift), det(pts) + shift, atol=1e-5)


def test_symmetric_loss_takes_the_best_relabelling():
    target = torch.tensor([[[0.0, 0, -1], [0.0, 0, 1]]])
    swapped = target[:, [1, 0]]
    sym = torch.tensor([[0, 1], [1, 0]])
    assert symmetric_keypoint_loss(swapped, target, sym).item() == 0.0
    assert symmetric_keypoint_loss(swapped, target, sym[:1]).item() == 4.0


def test_a_few_supervised_steps_reduce_the_loss():
    torch.manual_seed(0)
    m = build_models(0.75, {"vertical": 0.75})["end_fitting"]
    rng = np.random.default_rng(0)
    clouds, targets = [], []
    for _ in range(8):
        rot, t = random_rotation(rng), np.array([0.0, 0.0, 0.5]) + rng.normal(scale=0.02, size=3)
        clouds.append(torch.tensor(synthetic_view(m, rot, t, 64, rng, dense=2048)[:48], dtype=torch.float32))
        targets.append(
            transform(torch.tensor(m.keypoints).float(), torch.tensor(rot).float(), torch.tensor(t).float())
        )
    x, y = torch.stack(clouds), torch.stack(targets)
    sym = torch.as_tensor(m.symmetries)
    det = KeypointDetector(len(m.keypoint_names), m.diameter / 2, width=16)
    opt = torch.optim.Adam(det.parameters(), lr=5e-3)
    losses = []
    for _ in range(15):
        opt.zero_grad()
        loss = symmetric_keypoint_loss(det(x), y, sym)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0]
