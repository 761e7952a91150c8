"""Supervised C-3PO: train a part's keypoint detector on synthetic point clouds of its CAD model.

Paper §V.E: "The supervised portion of C-3PO was trained using only the CAD models". Each sample is
a partial view (:mod:`tlt_vision.cad.views`) of the model at a random rotation (uniform on SO(3))
and a random position in front of the camera, with depth noise; the target is the posed CAD
keypoints, and the loss takes the best of the model's symmetric relabellings. After every epoch it
prints the training and validation keypoint errors and the fraction of validation views whose pose
(detector + corrector) is certified. It writes ``<out>.pt`` and its manifest (:mod:`weights`).

Run::

    python -m tlt_tools.vision_training.c3po_supervised --model end_fitting \\
        --out build/vision/end_fitting.pt
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np
import torch

from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import load_mission
from tlt_vision.cad.models import CadModel, models_for_mission
from tlt_vision.cad.views import random_rotation, synthetic_view
from tlt_vision.ops.registration import transform
from tlt_vision.pose.detector import KeypointDetector, symmetric_keypoint_loss
from tlt_vision.pose.detector_weights import save_detector
from tlt_vision.pose.estimator import PoseEstimator


@dataclass(frozen=True)
class SupervisedConfig:
    train_samples: int = 2000
    val_samples: int = 200
    points: int = 256
    epochs: int = 20
    batch: int = 32
    width: int = 32
    lr: float = 2e-3
    noise: float = 0.001  # m, depth-camera noise
    distance: tuple[float, float] = (0.5, 1.5)  # m, part centre ahead of the camera
    lateral: float = 0.15  # m, off the optical axis
    certify_samples: int = 32  # validation views run through the whole estimator each epoch
    seed: int = 0


def make_views(
    model: CadModel, n: int, cfg: SupervisedConfig, rng: np.random.Generator
) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` views (n, points, 3) and their posed keypoints (n, K, 3), camera frame."""
    clouds, targets = [], []
    kp = torch.as_tensor(model.keypoints, dtype=torch.float32)
    while len(clouds) < n:
        rot = random_rotation(rng)
        t = np.array(
            [
                rng.uniform(-cfg.lateral, cfg.lateral),
                rng.uniform(-cfg.lateral, cfg.lateral),
                rng.uniform(*cfg.distance),
            ]
        )
        view = synthetic_view(model, rot, t, cfg.points, rng, noise=cfg.noise)
        if len(view) < 16:
            continue  # seen edge-on: nothing to learn from
        if len(view) < cfg.points:  # pad by repeating points: max and mean pooling barely notice
            view = view[rng.choice(len(view), cfg.points, replace=True)]
        clouds.append(torch.as_tensor(view, dtype=torch.float32))
        targets.append(
            transform(kp, torch.as_tensor(rot, dtype=torch.float32), torch.as_tensor(t, dtype=torch.float32))
        )
    return torch.stack(clouds), torch.stack(targets)


def certified_fraction(estimator: PoseEstimator, clouds: torch.Tensor) -> float:
    estimates = estimator.estimate_batch([c.numpy() for c in clouds])
    return sum(e.certified for e in estimates) / max(len(estimates), 1)


def train_supervised(
    model: CadModel,
    threshold: float,
    cfg: SupervisedConfig,
    progress: Callable[[str], None] = print,
) -> tuple[KeypointDetector, list[dict[str, float]]]:
    """Train a detector for ``model``; returns it and one record of figures per epoch."""
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    progress(f"{model.name}: generating {cfg.train_samples} training and {cfg.val_samples} validation views")
    x_tr, y_tr = make_views(model, cfg.train_samples, cfg, rng)
    x_va, y_va = make_views(model, cfg.val_samples, cfg, rng)
    sym = torch.as_tensor(model.symmetries)
    scale = model.diameter / 2
    det = KeypointDetector(len(model.keypoint_names), scale, cfg.width)
    opt = torch.optim.Adam(det.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(cfg.epochs, 1))
    history = []
    for epoch in range(1, cfg.epochs + 1):
        t0 = time.monotonic()
        det.train()
        order = torch.randperm(len(x_tr))
        total = 0.0
        for i in range(0, len(order), cfg.batch):
            idx = order[i : i + cfg.batch]
            loss = symmetric_keypoint_loss(det(x_tr[idx]), y_tr[idx], sym) / scale**2
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
        sched.step()
        det.eval()
        with torch.no_grad():
            val = float(symmetric_keypoint_loss(det(x_va), y_va, sym)) / scale**2
        record = {"epoch": epoch, "train_loss": total / len(x_tr), "val_loss": val}
        if cfg.certify_samples:
            est = PoseEstimator(model, det, threshold)
            record["val_certified"] = certified_fraction(est, x_va[: cfg.certify_samples])
        history.append(record)
        rms_mm = (val**0.5) * scale * 1000
        cert = f", certified {record['val_certified']:.0%}" if "val_certified" in record else ""
        progress(
            f"epoch {epoch}/{cfg.epochs}: train {record['train_loss']:.4f}, val {val:.4f} "
            f"(keypoint RMS {rms_mm:.1f} mm){cert}, {time.monotonic() - t0:.1f} s"
        )
    return det, history


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], prog="c3po_supervised")
    p.add_argument(
        "--mission", default="missions/one_bay.yaml", help="mission whose geometry sizes the parts"
    )
    p.add_argument("--model", required=True, help="CAD model name, e.g. end_fitting, strut_tube/vertical")
    p.add_argument("--out", required=True, help="weights file to write (.pt; the manifest goes beside it)")
    defaults = SupervisedConfig()
    for name in (
        "train_samples",
        "val_samples",
        "points",
        "epochs",
        "batch",
        "width",
        "certify_samples",
        "seed",
    ):
        p.add_argument(f"--{name.replace('_', '-')}", type=int, default=getattr(defaults, name))
    for name in ("lr", "noise"):
        p.add_argument(f"--{name}", type=float, default=getattr(defaults, name))
    args = p.parse_args(argv)
    try:
        mission = load_mission(args.mission)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    models = models_for_mission(mission)
    if args.model not in models:
        print(f"error: unknown model {args.model!r}; known: {', '.join(sorted(models))}", file=sys.stderr)
        return 2
    model = models[args.model]
    thresholds = mission.inspection["chamfer_thresholds"]
    if model.object_class not in thresholds:
        print(f"error: {args.mission} has no chamfer threshold for {model.object_class}", file=sys.stderr)
        return 2
    cfg = SupervisedConfig(
        **{k: getattr(args, k) for k in SupervisedConfig.__dataclass_fields__ if hasattr(args, k)}
    )
    det, history = train_supervised(
        model, thresholds[model.object_class], cfg, lambda s: print(s, flush=True)
    )
    training = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(cfg).items()}
    manifest = save_detector(det, model, args.out, {"stage": "supervised", **training}, history)
    print(f"wrote {args.out} and {manifest}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
