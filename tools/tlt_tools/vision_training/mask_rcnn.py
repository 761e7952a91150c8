"""Train the plain-torch Mask R-CNN on rendered image sets, and evaluate its mask AP50.

Train (``--train`` one or more sets, read as one, and optionally ``--val``, in the format of
:mod:`tlt_tools.vision_training.dataset`)::

    python -m tlt_tools.vision_training.mask_rcnn --train DIR [DIR ...] [--val DIR] \\
        --out build/vision/mask_rcnn.pt \\
        [--epochs 20] [--batch 4] [--lr 1e-3] [--seed 0] [--threads 2] [--max-size 320] \\
        [--device cpu|cuda] [--workers N] [--ranks N] [--time-budget-min M] [--config key=value ...]
        [--resume CKPT] [--init WEIGHTS]

Every ``--log-every`` steps it prints the epoch, step, images per second, the five losses and the
time left; after each epoch the validation mask AP50 per class and mean. It keeps the weights of
the best epoch by validation AP (the last epoch without ``--val``) in ``--out`` with their manifest
(kind ``mask_rcnn``; settings: the model configuration and ``max_size``, the input size the
node then uses too; figures: epochs, images, losses, AP50 per class, seconds). Beside it:
``<stem>_checkpoint.pt`` after every epoch (``--resume`` continues from it), ``<stem>_curves.png``
(losses per step, smoothed; validation AP per epoch) and ``<stem>_samples.png`` (validation images
with the predicted masks, boxes, classes and scores). ``--init WEIGHTS`` starts from trained
weights (the tensors of the same name and shape; a part the model adds, such as a semantic head,
starts fresh), so that short runs on lent machines can build on each other.

Evaluate saved weights::

    python -m tlt_tools.vision_training.mask_rcnn --evaluate build/vision/mask_rcnn.pt --val DIR [--threads 2]

prints AP50 per class and mean and the mean inference time per image (as the node runs it:
:func:`tlt_vision.segmentation.inference.detect_rgb`, full-size image in, full-size masks out).

With ``--node-config config/vision/node.yaml`` the validation AP (in training, and so the best
epoch, and with ``--evaluate``) is that of the masks as the vision node makes them
(:meth:`tlt_vision.segmentation_source.MaskRcnnSegmenter.refine`: its inference settings, the
depth cut of thin parts, the trim and the exclusive overlaps), not the model's alone: the figure
the benchmark holds to its goal.

An input that cannot be used (not an image set, another class list, no images, unreadable or
mismatched checkpoint or weights) ends the command with exit status 2 and the path and reason on
stderr.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import torch

from tlt_tools.vision_training.data_parallel import run_ranks
from tlt_tools.vision_training.dataset import DatasetError
from tlt_tools.vision_training.mask_rcnn_data import InputError, open_set, resolve_device
from tlt_tools.vision_training.mask_rcnn_evaluation import evaluate, node_segmenter
from tlt_tools.vision_training.mask_rcnn_training import refuse_bad_inputs, train
from tlt_vision.segmentation.inference import load_mask_rcnn
from tlt_vision.weights import WeightsError


def evaluate_command(args: argparse.Namespace) -> int:
    torch.set_num_threads(args.threads)
    device = resolve_device(args.device)
    try:
        model, manifest = load_mask_rcnn(args.evaluate)
    except WeightsError as exc:
        raise InputError(str(exc)) from exc
    model.to(device)
    max_size = manifest["settings"].get("max_size")
    images = open_set(args.val, model.cfg.classes)
    node = node_segmenter(args.node_config, model, max_size) if args.node_config else None
    result = evaluate(model, images, max_size, args.val_limit, node)
    print(
        f"{args.evaluate} on {images.root} ({result['images']} images, max size {max_size or 'full'}, "
        f"{args.threads} threads, {device}), "
        + (f"as the node segments ({args.node_config})" if node is not None else "the model alone")
    )
    for c in model.cfg.classes:
        ap = result["per_class"].get(c)
        print(f"  {c:<14} AP50 {ap:.3f}" if ap is not None else f"  {c:<14} AP50 -  (no instances)")
    print(f"  mean           AP50 {result['map']:.3f}")
    print(f"  inference {result['seconds_per_image'] * 1e3:.0f} ms per image")
    return 0


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tlt_tools.vision_training.mask_rcnn", description=__doc__.split("\n")[0]
    )
    p.add_argument(
        "--train", nargs="+", help="training image sets (directories with index.json), read as one"
    )
    p.add_argument("--val", help="validation image set: AP50 after each epoch, best epoch kept")
    p.add_argument(
        "--out", default="build/vision/mask_rcnn.pt", help="weights file (.pt); manifest beside it"
    )
    p.add_argument("--epochs", type=int, default=20)
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--lr", type=float, default=1e-3, help="AdamW peak learning rate")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument(
        "--device", default="cpu", help="torch device to train and evaluate on (cpu, cuda, cuda:1)"
    )
    p.add_argument(
        "--workers",
        type=int,
        default=0,
        help="processes loading and augmenting training images (0: the training process); "
        "with --ranks, each training process's",
    )
    p.add_argument(
        "--ranks",
        type=int,
        default=1,
        help="training processes on the device, each on --batch images of every step, their "
        "gradients averaged (the step's batch is --batch times --ranks)",
    )
    p.add_argument(
        "--max-size",
        type=int,
        default=None,
        help="downscale images so the longest side is at most this (pixels); recorded in the "
        "manifest so inference uses the same size (default: full size)",
    )
    p.add_argument(
        "--min-area",
        type=int,
        default=4,
        help="drop training instances with fewer pixels than this at the model's size",
    )
    p.add_argument(
        "--sensor-noise",
        type=float,
        default=0.0,
        metavar="GREY_LEVELS",
        help="Gaussian colour noise of each training image, 1 sigma uniform in 0..this grey"
        " levels of 255, as a real camera's sensor adds (default 0: none)",
    )
    p.add_argument(
        "--blur",
        type=float,
        default=0.0,
        metavar="PIXELS",
        help="Gaussian blur of each training image, sigma uniform in 0..this pixels at the"
        " model's size, as real optics add (default 0: none)",
    )
    p.add_argument(
        "--config",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="MaskRCNNConfig field (JSON value), e.g. fpn_channels=32; repeatable",
    )
    p.add_argument(
        "--time-budget-min",
        type=float,
        default=None,
        help="train only the epochs that fit in this many minutes, judged from the epochs run "
        "(the learning rate's decay is fitted to them)",
    )
    p.add_argument("--log-every", type=int, default=10, help="steps between progress lines")
    p.add_argument("--val-limit", type=int, default=None, help="evaluate on the first N validation images")
    p.add_argument(
        "--node-config",
        metavar="NODE_YAML",
        help="validate the masks as the vision node configured by this file makes them "
        "(e.g. config/vision/node.yaml), not the model's alone",
    )
    p.add_argument("--resume", help="checkpoint (<out stem>_checkpoint.pt) to continue from")
    p.add_argument(
        "--init",
        metavar="WEIGHTS",
        help="start from these trained weights (tensors of the same name and shape)",
    )
    p.add_argument(
        "--evaluate", metavar="WEIGHTS", help="evaluate these weights on --val instead of training"
    )
    args = p.parse_args(argv)
    for name in ("epochs", "batch", "threads", "log_every", "ranks"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1")
    if args.workers < 0:
        p.error("--workers must be at least 0")
    if args.time_budget_min is not None and args.time_budget_min <= 0:
        p.error("--time-budget-min must be positive")
    if not 0.0 <= args.sensor_noise <= 64.0:
        p.error(f"--sensor-noise {args.sensor_noise:g}: grey levels from 0 to 64")
    if not 0.0 <= args.blur <= 5.0:
        p.error(f"--blur {args.blur:g}: pixels from 0 to 5")
    if args.max_size is not None and args.max_size < 32:
        p.error("--max-size must be at least 32 pixels")
    if args.init and args.resume:
        p.error("--init and --resume exclude each other (a checkpoint holds the weights)")
    if args.evaluate and not args.val:
        p.error("--evaluate needs --val")
    if args.node_config and not args.val:
        p.error("--node-config needs --val")
    if not args.evaluate and not args.train:
        p.error("--train is required (or --evaluate WEIGHTS --val DIR)")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        if args.evaluate:
            return evaluate_command(args)
        if args.ranks > 1:
            refuse_bad_inputs(args)
        return run_ranks(train, args.ranks, args, refused=(InputError, DatasetError))
    except (InputError, DatasetError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
