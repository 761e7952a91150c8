"""Self-supervised C-3PO: a part's keypoint detector trained on the twin's rendered scenes.

Paper §V.E, after the supervised stage (:mod:`c3po_supervised`, CAD models only): the detector is
refined on point clouds of real scenes without pose labels. Each epoch the whole estimator the
vision node runs (detector, corrector, pose refinement, certificate: ``config/vision/node.yaml``)
poses every training cloud; the clouds whose pose is *certified* become training samples, their
target the corrected keypoints, and the detector is trained one pass on them. Uncertified poses
teach nothing: the certificate is the only judge of a pseudo-label, no ground truth is read.

Training stops when the certified fraction of the validation clouds reaches ``target`` (95 %), or
when it has not improved for ``patience`` epochs; the detector of the best validation epoch is the
one written. A view the certificate finds degenerate (a tube whose ends are hidden, a cube seen
face-on) stays uncertified whatever the detector does, which is why learning can stop below the
target. Where the images carry poses (the twin's), each epoch also reports the ADD-S of the
certified validation poses against them: a figure to read, never a training signal.

The clouds are those the vision node would see, from the twin's instance masks (a cross frame's
sides joined into one part) through :meth:`tlt_vision.pipeline.PartPipeline.cloud`.

Run::

    python -m tlt_tools.vision_training.c3po_self_supervised --model corner_joint \\
        --images /tmp/vis/ssl --val /tmp/vis/val --out build/vision/corner_joint.pt --plot curves.png

It writes ``<out>.pt`` with its manifest (the settings of the detector it started from, the
training settings, the figures of every epoch and why it stopped); the vision node takes it where
``config/vision/node.yaml`` ``detectors`` names it.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from tlt_common.config_schema import ConfigError
from tlt_common.mission.schema import load_mission
from tlt_tools.vision_training.dataset import DatasetError, ImageSet, ImageSets, instance_model, instance_part
from tlt_vision.cad.models import CadModel
from tlt_vision.detections import Detection
from tlt_vision.node_config import load_config
from tlt_vision.part_inspection import load_estimators
from tlt_vision.pipeline import PartPipeline
from tlt_vision.pointcloud import Intrinsics
from tlt_vision.pose.detector import KeypointDetector, symmetric_keypoint_loss
from tlt_vision.pose.detector_weights import save_detector
from tlt_vision.pose.errors import add_s
from tlt_vision.pose.estimator import PoseEstimate, PoseEstimator, padded_batch
from tlt_vision.weights import WeightsError, read_manifest

ADD_S_FRACTION = 0.02  # of the part's size: the accuracy bar for a certified pose


@dataclass(frozen=True)
class SelfSupervisedConfig:
    epochs: int = 10
    patience: int = 2  # epochs without a better validation certified fraction before stopping
    target: float = 0.95  # validation certified fraction that ends training
    batch: int = 32
    lr: float = 1e-4  # fine-tuning: 1e-3 moved a supervised detector away from the corrector's basin
    label_batch: int = 64  # clouds posed at once when labelling (memory, not results)
    seed: int = 0


@dataclass(frozen=True)
class SceneCloud:
    """One part's observed cloud (N, 3), camera frame, and where it came from."""

    points: np.ndarray
    source: str  # image file and instance name
    true_pose: np.ndarray | None = None  # 4x4 model-to-camera, when the images carry it


@dataclass
class Evaluation:
    """How the estimator does on a set of clouds."""

    clouds: int
    certified: int
    observably_correct: int
    non_degenerate: int
    add_s_ok: int | None = None  # certified poses with ADD-S under 2 % of size (poses known)
    estimates: list[PoseEstimate] = field(default_factory=list, repr=False)

    @property
    def certified_fraction(self) -> float:
        return self.certified / self.clouds if self.clouds else 0.0

    def figures(self, prefix: str) -> dict[str, float | int | None]:
        out: dict[str, float | int | None] = {
            f"{prefix}_clouds": self.clouds,
            f"{prefix}_certified": self.certified_fraction,
            f"{prefix}_observably_correct": self.observably_correct / max(self.clouds, 1),
            f"{prefix}_non_degenerate": self.non_degenerate / max(self.clouds, 1),
        }
        if self.add_s_ok is not None:
            out[f"{prefix}_add_s_ok"] = self.add_s_ok / self.certified if self.certified else None
        return out


def scene_clouds(
    images: ImageSet | ImageSets, model_name: str, pipeline: PartPipeline, limit: int | None = None
) -> list[SceneCloud]:
    """The clouds of every instance of CAD model ``model_name`` in ``images`` that give one.

    A part drawn as several instances (a cross frame's sides) is joined into one, as the vision
    node joins them; an instance without a usable cloud (too few points, no depth) is left out.
    """
    out: list[SceneCloud] = []
    for i in range(len(images)):
        s = images[i]
        intrinsics = Intrinsics.from_matrix(s.intrinsics)
        parts: dict[str, list[int]] = {}
        for j, (label, name) in enumerate(zip(s.labels, s.names, strict=True)):
            cls = images.classes[int(label) - 1]
            if instance_model(cls, str(name)) == model_name:
                parts.setdefault(instance_part(cls, str(name)), []).append(j)
        for part, members in parts.items():
            mask = np.logical_or.reduce([s.masks[j] for j in members])
            cloud = pipeline.cloud(Detection(model_name, mask), s.depth, intrinsics)
            if cloud.ok:
                out.append(
                    SceneCloud(
                        cloud.points.astype(np.float32),
                        f"{images.path(i).name}:{part}",
                        np.asarray(s.poses[members[0]], dtype=float),
                    )
                )
            if limit is not None and len(out) >= limit:
                return out
    return out


def evaluate(estimator: PoseEstimator, clouds: Sequence[SceneCloud], label_batch: int) -> Evaluation:
    """Pose every cloud with the whole estimator and count what its certificates say."""
    estimates: list[PoseEstimate] = []
    for k in range(0, len(clouds), label_batch):
        estimates += estimator.estimate_batch([c.points for c in clouds[k : k + label_batch]])
    cert = [e.certificate for e in estimates]
    result = Evaluation(
        len(clouds),
        sum(c.certified for c in cert),
        sum(c.observably_correct for c in cert),
        sum(c.non_degenerate for c in cert),
        estimates=estimates,
    )
    if clouds and all(c.true_pose is not None for c in clouds):
        model = estimator.model
        result.add_s_ok = sum(
            add_s(model, e.rotation, e.translation, c.true_pose[:3, :3], c.true_pose[:3, 3])
            < ADD_S_FRACTION * model.diameter
            for e, c in zip(estimates, clouds, strict=True)
            if e.certified
        )
    return result


def train_epoch(
    detector: KeypointDetector,
    model: CadModel,
    samples: Sequence[tuple[np.ndarray, np.ndarray]],
    optimiser: torch.optim.Optimizer,
    batch: int,
    generator: torch.Generator,
) -> float:
    """One pass over ``samples`` [(cloud, target keypoints)]; returns the mean loss (scaled like the
    supervised stage's: squared error over the squared half-size)."""
    detector.train()
    sym = torch.as_tensor(model.symmetries)
    scale2 = (model.diameter / 2) ** 2
    order = torch.randperm(len(samples), generator=generator).tolist()
    total = 0.0
    for k in range(0, len(order), batch):
        chosen = [samples[i] for i in order[k : k + batch]]
        obs, mask = padded_batch([c for c, _ in chosen])
        target = torch.as_tensor(np.stack([t for _, t in chosen]), dtype=torch.float32)
        loss = symmetric_keypoint_loss(detector(obs, mask), target, sym) / scale2
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        total += float(loss.detach()) * len(chosen)
    detector.eval()
    return total / max(len(samples), 1)


def train_self_supervised(
    estimator: PoseEstimator,
    train: Sequence[SceneCloud],
    val: Sequence[SceneCloud],
    cfg: SelfSupervisedConfig,
    progress: Callable[[str], None] = print,
) -> tuple[KeypointDetector, list[dict], str]:
    """Self-supervise ``estimator``'s detector (changed in place, left at its best epoch).

    Returns the detector, one record of figures per epoch (epoch 0: the starting detector) and
    why training stopped.
    """
    if not train or not val:
        raise ValueError(f"need training and validation clouds (got {len(train)} and {len(val)})")
    torch.manual_seed(cfg.seed)
    generator = torch.Generator().manual_seed(cfg.seed)
    detector = estimator.detector
    optimiser = torch.optim.Adam(detector.parameters(), lr=cfg.lr)
    t0 = time.monotonic()
    first = evaluate(estimator, val, cfg.label_batch)
    history = [{"epoch": 0, **first.figures("val"), "seconds": time.monotonic() - t0}]
    progress(_line(0, cfg.epochs, first, None, None, time.monotonic() - t0))
    best, best_state, since_best = first.certified_fraction, copy.deepcopy(detector.state_dict()), 0
    if best >= cfg.target:
        return detector, history, f"the starting detector certifies {best:.1%} >= {cfg.target:.0%}"
    reason = f"{cfg.epochs} epochs run"
    for epoch in range(1, cfg.epochs + 1):
        t0 = time.monotonic()
        labelled = evaluate(estimator, train, cfg.label_batch)
        samples = [
            (c.points, e.keypoints) for c, e in zip(train, labelled.estimates, strict=True) if e.certified
        ]
        if not samples:
            reason = f"epoch {epoch}: no training cloud certified, nothing to learn from"
            break
        loss = train_epoch(detector, estimator.model, samples, optimiser, cfg.batch, generator)
        result = evaluate(estimator, val, cfg.label_batch)
        seconds = time.monotonic() - t0
        history.append(
            {
                "epoch": epoch,
                "train_loss": loss,
                **labelled.figures("train"),
                **result.figures("val"),
                "seconds": seconds,
            }
        )
        progress(_line(epoch, cfg.epochs, result, labelled, loss, seconds))
        if result.certified_fraction > best:
            best, best_state, since_best = result.certified_fraction, copy.deepcopy(detector.state_dict()), 0
        else:
            since_best += 1
        if best >= cfg.target:
            reason = f"epoch {epoch}: validation certified {best:.1%} >= {cfg.target:.0%}"
            break
        if since_best >= cfg.patience:
            reason = f"epoch {epoch}: no better validation certified fraction for {cfg.patience} epochs"
            break
    detector.load_state_dict(best_state)
    detector.eval()
    return detector, history, reason


def _line(
    epoch: int, epochs: int, val: Evaluation, train: Evaluation | None, loss: float | None, seconds: float
) -> str:
    text = f"epoch {epoch}/{epochs}: "
    if train is not None and loss is not None:
        text += f"{train.certified}/{train.clouds} training clouds certified, loss {loss:.4f}; "
    text += (
        f"validation certified {val.certified_fraction:.1%} (observably correct "
        f"{val.observably_correct / max(val.clouds, 1):.1%}, non-degenerate "
        f"{val.non_degenerate / max(val.clouds, 1):.1%})"
    )
    if val.add_s_ok is not None and val.certified:
        text += f", ADD-S ok {val.add_s_ok / val.certified:.1%} of certified"
    return text + f", {seconds:.1f} s"


def plot_history(history: list[dict], title: str, path: str | Path) -> Path:
    """Validation certified fraction (and its parts) and training loss by epoch, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [h["epoch"] for h in history]
    fig, (ax, lx) = plt.subplots(1, 2, figsize=(10, 4))
    # Certified is the lower of its two conditions and often equal to one: drawn wide, underneath.
    curves = (
        ("val_certified", "certified", 5),
        ("val_observably_correct", "observably correct", 1.5),
        ("val_non_degenerate", "non-degenerate", 1.5),
        ("val_add_s_ok", "ADD-S ok (of certified)", 1.5),
    )
    for key, label, width in curves:
        points = [(e, h[key]) for e, h in zip(epochs, history, strict=True) if h.get(key) is not None]
        if points:
            ax.plot(*zip(*points, strict=True), marker="o", label=label, linewidth=width)
    ax.axhline(0.95, color="grey", linestyle="--", linewidth=1, label="goal 95 %")
    ax.set(xlabel="epoch", ylabel="fraction of validation clouds", ylim=(0, 1.02), title=title)
    ax.legend(loc="lower right", fontsize=8)
    losses = [(h["epoch"], h["train_loss"]) for h in history if "train_loss" in h]
    if losses:
        lx.plot(*zip(*losses, strict=True), marker="o")
    lx.set(xlabel="epoch", ylabel="keypoint loss on certified clouds", title="training loss")
    for axis in (ax, lx):
        axis.xaxis.get_major_locator().set_params(integer=True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], prog="c3po_self_supervised")
    p.add_argument("--model", required=True, help="CAD model name, e.g. corner_joint, strut_tube/diagonal")
    p.add_argument("--images", nargs="+", required=True, type=Path, help="rendered image sets to train on")
    p.add_argument("--val", nargs="+", required=True, type=Path, help="rendered image sets to validate on")
    p.add_argument("--out", required=True, type=Path, help="weights file to write (.pt; manifest beside it)")
    p.add_argument(
        "--config",
        type=Path,
        default=Path("config/vision/node.yaml"),
        help="vision node configuration: the starting detector, corrector and cloud settings",
    )
    p.add_argument("--mission", type=Path, default=Path("missions/one_bay.yaml"))
    p.add_argument("--limit", type=int, help="at most this many training clouds")
    p.add_argument("--val-limit", type=int, help="at most this many validation clouds")
    p.add_argument("--plot", type=Path, help="write the training curves to this PNG")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    defaults = SelfSupervisedConfig()
    for name in ("epochs", "patience", "batch", "label_batch", "seed"):
        p.add_argument(f"--{name.replace('_', '-')}", type=int, default=getattr(defaults, name))
    for name in ("target", "lr"):
        p.add_argument(f"--{name}", type=float, default=getattr(defaults, name))
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    cfg = SelfSupervisedConfig(**{k: getattr(args, k) for k in SelfSupervisedConfig.__dataclass_fields__})
    try:
        mission = load_mission(args.mission)
        config = load_config(args.config, args.mission)
        if args.model not in config.raw["detectors"]:
            raise ConfigError(
                args.config, "detectors", f"no {args.model!r} (known: {', '.join(config.raw['detectors'])})"
            )
        start_path = config.detector_path(args.model)
        start = read_manifest(start_path)
        estimator = load_estimators(config, mission)[args.model]
        train_sets = ImageSets([ImageSet(d) for d in args.images])
        val_sets = ImageSets([ImageSet(d) for d in args.val])
    except (ConfigError, WeightsError, DatasetError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    pipeline = PartPipeline(
        {}, max_points=config.raw["max_points"], keep_border_below=config.raw["keep_border_below"]
    )
    print(
        f"{args.model}: reading clouds from {len(train_sets)} training and {len(val_sets)} validation images",
        flush=True,
    )
    train = scene_clouds(train_sets, args.model, pipeline, args.limit)
    val = scene_clouds(val_sets, args.model, pipeline, args.val_limit)
    for what, clouds, dirs in (("training", train, args.images), ("validation", val, args.val)):
        if not clouds:
            print(
                f"error: no usable cloud of {args.model} in the {what} images ({', '.join(map(str, dirs))})",
                file=sys.stderr,
            )
            return 2
    sizes = [len(c.points) for c in train]
    print(
        f"{len(train)} training clouds (median {statistics.median(sizes):.0f} points), "
        f"{len(val)} validation clouds; starting from {start_path}",
        flush=True,
    )
    detector, history, reason = train_self_supervised(
        estimator, train, val, cfg, lambda s: print(s, flush=True)
    )
    print(f"stopped: {reason}", flush=True)
    training = {
        "stage": "self_supervised",
        **asdict(cfg),
        "images": [str(d) for d in args.images],
        "val": [str(d) for d in args.val],
        "train_clouds": len(train),
        "val_clouds": len(val),
        "corrector": config.raw["corrector"],
        "started_from": {
            "path": str(start_path),
            "sha256": start.get("sha256"),
            "training": start.get("extra", {}).get("training"),
        },
        "stopped": reason,
    }
    manifest = save_detector(detector, estimator.model, args.out, training, history)
    print(f"wrote {args.out} and {manifest}")
    if args.plot:
        print(f"wrote {plot_history(history, f'self-supervised C-3PO: {args.model}', args.plot)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
