import torch

from tlt_vision.ops.nms import batched_nms, nms


def test_nms_hand_checked():
    boxes = torch.tensor(
        [
            [0.0, 0.0, 10.0, 10.0],  # 0: score 0.9, kept
            [1.0, 0.0, 11.0, 10.0],  # 1: IoU with 0 = 90/110 = 0.818 -> suppressed
            [0.0, 0.0, 10.0, 5.0],  # 2: IoU with 0 = 0.5 -> kept at threshold 0.5 (not strictly greater)
            [20.0, 20.0, 30.0, 30.0],  # 3: disjoint, kept
            [5.0, 0.0, 15.0, 10.0],  # 4: IoU with 0 = 50/150 = 1/3, with 2 = 25/125 = 0.2 -> kept
        ]
    )
    scores = torch.tensor([0.9, 0.95, 0.8, 0.3, 0.5])
    # 1 has the highest score: it is kept first and suppresses 0 (0.818); then 2 (IoU with 1:
    # 45/105 = 0.43) kept, 4 (IoU with 1: 60/140 = 0.43, with 2: 0.2) kept, 3 kept.
    assert nms(boxes, scores, 0.5).tolist() == [1, 2, 4, 3]
    # Threshold 0.4: 2 and 4 now overlap 1 too much.
    assert nms(boxes, scores, 0.4).tolist() == [1, 3]


def test_nms_empty():
    assert nms(torch.zeros(0, 4), torch.zeros(0), 0.5).numel() == 0


def test_batched_nms_keeps_labels_apart():
    boxes = torch.tensor([[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 10.0], [0.5, 0.0, 10.0, 10.0]])
    scores = torch.tensor([0.9, 0.8, 0.7])
    labels = torch.tensor([0, 1, 0])
    assert sorted(batched_nms(boxes, scores, labels, 0.5).tolist()) == [0, 1]


def test_nms_stops_at_max_keep_and_matches_the_walk_over_the_whole_iou_matrix():
    from tlt_vision.ops.boxes import box_iou

    gen = torch.Generator().manual_seed(0)
    xy = torch.rand(500, 2, generator=gen) * 80
    boxes = torch.cat([xy, xy + torch.rand(500, 2, generator=gen) * 40 + 1], dim=1)
    scores = torch.rand(500, generator=gen)
    order = torch.sort(scores, descending=True, stable=True).indices
    over = box_iou(boxes[order], boxes[order]) > 0.5
    suppressed, walk = torch.zeros(500, dtype=torch.bool), []
    for i in range(500):
        if not suppressed[i]:
            walk.append(int(order[i]))
            suppressed |= over[i]
    assert nms(boxes, scores, 0.5).tolist() == walk
    assert nms(boxes, scores, 0.5, max_keep=7).tolist() == walk[:7]
