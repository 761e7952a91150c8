"""The Mask R-CNN training run behind ``python -m tlt_tools.vision_training.mask_rcnn --train``:
the configuration and its overrides, the learning-rate schedule and the epochs a time budget
allows, checkpoints and initial weights, and :func:`train`, one process of a data-parallel run
(:mod:`tlt_tools.vision_training.data_parallel`)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tlt_tools.vision_training.data_parallel import Ranks
from tlt_tools.vision_training.dataset import ImageSet, ImageSets
from tlt_tools.vision_training.mask_rcnn_data import (
    Augment,
    InputError,
    TrainingImages,
    as_list,
    one_thread,
    open_set,
    open_sets,
    resolve_device,
    silent,
)
from tlt_tools.vision_training.mask_rcnn_evaluation import evaluate, format_ap, node_segmenter
from tlt_tools.vision_training.mask_rcnn_figures import LOSSES, SEMANTIC, plot_curves, plot_samples
from tlt_vision.segmentation.config import MaskRCNNConfig
from tlt_vision.segmentation.inference import KIND, load_mask_rcnn, weights_settings
from tlt_vision.segmentation.model import MaskRCNN, train_step
from tlt_vision.weights import WeightsError, read_manifest, save_weights

VERSION = "1"
SHORT = {
    "rpn_objectness": "rpn_obj",
    "rpn_box": "rpn_box",
    "roi_cls": "cls",
    "roi_box": "box",
    "roi_mask": "mask",
    SEMANTIC: "sem",
}


def output_paths(out: Path) -> dict[str, Path]:
    stem = out.with_suffix("")
    return {
        "checkpoint": Path(f"{stem}_checkpoint.pt"),
        "curves": Path(f"{stem}_curves.png"),
        "samples": Path(f"{stem}_samples.png"),
    }


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``key=value`` pairs (values as JSON: ``fpn_channels=32``, ``backbone_channels=[8,8,16,16]``)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"--config {item!r}: expected key=value")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def build_config(overrides: dict[str, Any]) -> MaskRCNNConfig:
    try:
        return MaskRCNNConfig.from_dict({**MaskRCNNConfig().to_dict(), **overrides})
    except (TypeError, ValueError) as exc:
        raise InputError(f"--config: {exc}") from exc


def learning_rate(step: int, total: int, base: float) -> float:
    """Linear warm-up over the first 5 % of steps (at most 200) from base/10, then cosine to base/20:
    a from-scratch detector's first steps have wild RPN gradients."""
    warm = max(1, min(200, total // 20))
    if step < warm:
        return base * (0.1 + 0.9 * step / warm)
    t = (step - warm) / max(1, total - warm)
    return base * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t)))


def epochs_within(budget_s: float, elapsed_s: float, epochs_run: int, epochs_done: int, epochs: int) -> int:
    """How many epochs (at most ``epochs``, at least those done) a run may have so it ends within
    ``budget_s``, at the mean duration of the ``epochs_run`` this run has trained and evaluated."""
    per_epoch = elapsed_s / max(epochs_run, 1)
    more = math.floor(max(budget_s - elapsed_s, 0.0) / per_epoch) if per_epoch > 0 else epochs
    return max(epochs_done, min(epochs, epochs_done + more))


def epochs_at_pace(budget_s: float, seconds_per_epoch: float, epochs_done: int, epochs: int) -> int:
    """How many epochs (at most ``epochs``, at least one more than ``epochs_done``, those before this
    run) fit in ``budget_s`` at ``seconds_per_epoch``, judged early in the run's first epoch."""
    fit = math.floor(budget_s / seconds_per_epoch) if seconds_per_epoch > 0 else epochs
    return max(epochs_done + 1, min(epochs, epochs_done + fit))


def pace_probe_step(steps_per_epoch: int) -> int:
    """The step of a run's first epoch after which ``--time-budget-min`` first judges the epochs
    that fit (0: none, a one-step epoch): 5 % of the epoch, or 20 steps if more, so that an epoch
    longer than the budget decays the learning rate over itself instead of holding it at its peak."""
    return max(steps_per_epoch // 20, min(20, steps_per_epoch - 1))


def _budget_line(minutes: float, fit: int, epochs: int, how: str = "") -> str:
    return (
        f"time budget {minutes:g} min: {fit} epochs fit, not {epochs}{how}; "
        "the learning rate decays over those"
    )


def _duration(seconds: float) -> str:
    seconds = round(seconds)
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else f"{m}m{s:02d}s"


def _save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    tmp.replace(path)  # a run killed while writing keeps its previous checkpoint


def validated_as(args: argparse.Namespace) -> str | None:
    """Which masks a run's validation scores (the manifest's and each epoch's ``val_as``); None
    without ``--val``."""
    if not args.val:
        return None
    return f"as the node segments ({args.node_config})" if args.node_config else "the model alone"


def _load_checkpoint(
    path: Path, settings: dict[str, Any], classes: Sequence[str], val_as: str | None
) -> dict[str, Any]:
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError as exc:
        raise InputError(f"{path}: checkpoint not found") from exc
    except Exception as exc:  # torch raises several types for a corrupt file
        raise InputError(f"{path}: unreadable checkpoint: {exc}") from exc
    if not isinstance(ckpt, dict) or ckpt.get("kind") != f"{KIND}_checkpoint":
        raise InputError(f"{path}: not a Mask R-CNN training checkpoint")
    if ckpt["classes"] != list(classes):
        raise InputError(f"{path}: checkpoint classes {ckpt['classes']} differ from {list(classes)}")
    if ckpt["settings"] != settings:
        diff = sorted(
            k
            for k in set(settings["model"]) | set(ckpt["settings"]["model"])
            if settings["model"].get(k) != ckpt["settings"]["model"].get(k)
        )
        if ckpt["settings"].get("max_size") != settings.get("max_size"):
            diff.append("max_size")
        raise InputError(
            f"{path}: checkpoint was trained with other settings ({', '.join(diff)}); "
            "resume with the same --config and --max-size"
        )
    validated = [h.get("val_as", "the model alone") for h in ckpt["history"] if h.get("val_map") is not None]
    if val_as is not None and validated and validated[-1] != val_as:
        raise InputError(
            f"{path}: its epochs were validated {validated[-1]}, this run's would be "
            f"{val_as} (the best epoch would be chosen by two measures); resume with the "
            "same --node-config"
        )
    return ckpt


def init_from(model: MaskRCNN, path: Path, classes: Sequence[str]) -> list[str]:
    """Copy into ``model`` the tensors of Mask R-CNN weights ``path`` that it has by the same name and
    shape; returns the names it has that the file does not give (left as initialised). InputError
    for weights of another kind or class list, or that give less than half the model's parameters."""
    try:
        manifest = read_manifest(path)
    except WeightsError as exc:
        raise InputError(str(exc)) from exc
    if manifest["kind"] != KIND or manifest["classes"] != list(classes):
        raise InputError(
            f"{path}: --init needs {KIND} weights for classes {list(classes)}, not "
            f"{manifest['kind']} weights for {manifest['classes']}"
        )
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several types for a corrupt file
        raise InputError(f"{path}: unreadable weights: {exc}") from exc
    own = model.state_dict()
    given = {k: v for k, v in state.items() if k in own and own[k].shape == v.shape}
    params = dict(model.named_parameters())
    total = sum(v.numel() for v in params.values())
    share = sum(v.numel() for k, v in params.items() if k in given) / max(total, 1)
    if share < 0.5:  # a model of another size: a few biases would match, nothing learned would carry
        raise InputError(f"{path}: gives only {share:.0%} of the model's parameters (another --config?)")
    model.load_state_dict(given, strict=False)
    return sorted(set(own) - set(given))


@dataclass(frozen=True)
class Inputs:
    """What a training run reads, opened and checked."""

    cfg: MaskRCNNConfig
    settings: dict[str, Any]
    train_set: ImageSets
    val_set: ImageSet | None
    device: torch.device
    out: Path


def open_inputs(args: argparse.Namespace) -> Inputs:
    """The run's inputs; InputError for the first that cannot be used (``--init`` and ``--resume``
    are read, and refused, where the run loads them)."""
    cfg = build_config(parse_overrides(args.config))
    settings = weights_settings(cfg, args.max_size)
    train_set = open_sets(args.train, cfg.classes)
    device = resolve_device(args.device)
    val_set = open_set(args.val, cfg.classes) if args.val else None
    out = Path(args.out)
    if out.suffix != ".pt":
        raise InputError(f"{out}: --out must end in .pt")
    if len(train_set) < args.batch * args.ranks:
        raise InputError(
            f"{', '.join(map(str, train_set.roots))}: {len(train_set)} images, fewer than "
            f"--batch {args.batch} times --ranks {args.ranks}"
        )
    if args.node_config:
        node_segmenter(args.node_config, MaskRCNN(cfg), args.max_size)  # refused here, not after an epoch
    return Inputs(cfg, settings, train_set, val_set, device, out)


def refuse_bad_inputs(args: argparse.Namespace) -> None:
    """Every InputError the run's inputs give, weights and checkpoint included, raised here: with
    ``--ranks`` the command calls this before it starts the processes, so that a bad input is
    refused once, with exit status 2, not by every process."""
    inputs = open_inputs(args)
    if args.init:
        init_from(MaskRCNN(inputs.cfg), Path(args.init), inputs.cfg.classes)
    if args.resume:
        _load_checkpoint(Path(args.resume), inputs.settings, inputs.cfg.classes, validated_as(args))


def train(args: argparse.Namespace, ranks: Ranks | None = None) -> int:
    """Train as ``args`` say; with ``ranks`` as one of several processes (``--ranks``), each on its
    share of every step's batch, the leader alone printing, validating and saving."""
    ranks = ranks or Ranks()
    say = print if ranks.leader else silent
    inputs = open_inputs(args)
    cfg, settings, train_set, val_set, device, out = (
        inputs.cfg,
        inputs.settings,
        inputs.train_set,
        inputs.val_set,
        inputs.device,
        inputs.out,
    )
    paths = output_paths(out)
    if ranks.leader:
        out.parent.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    model = MaskRCNN(cfg)
    if args.init:
        fresh = init_from(model, Path(args.init), cfg.classes)
        say(
            f"initialised from {args.init}"
            + (f"; {len(fresh)} tensors fresh, from {fresh[0]}" if fresh else ""),
            flush=True,
        )
    model.to(device)
    node = None
    if args.node_config and ranks.leader:  # only the leader validates
        node = node_segmenter(args.node_config, model, args.max_size)
    val_as = validated_as(args)
    optimizer = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    aug = Augment(noise=args.sensor_noise, blur=args.blur)
    loss_keys = (*LOSSES, SEMANTIC) if cfg.semantic_classes else LOSSES
    steps_per_epoch = len(ranks.batches(range(len(train_set)), args.batch))
    epochs = args.epochs  # lowered by --time-budget-min once the run's pace is known
    total_steps = epochs * steps_per_epoch
    history: list[dict[str, Any]] = []
    step_losses: list[dict[str, float]] = []
    best_map, start_epoch, seconds_before = -1.0, 0, 0.0
    if args.resume:
        ckpt = _load_checkpoint(Path(args.resume), settings, cfg.classes, validated_as(args))
        model.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        torch.set_rng_state(ckpt["torch_rng"])
        history, step_losses = ckpt["history"], ckpt["step_losses"]
        best_map, start_epoch, seconds_before = ckpt["best_map"], ckpt["epoch"], ckpt["seconds"]
        say(f"resuming {args.resume} after epoch {start_epoch}", flush=True)
        if start_epoch >= epochs:
            say(f"nothing to do: the checkpoint has {start_epoch} epochs, --epochs is {epochs}")
    ranks.same_as_leader(model)
    if ranks.size > 1:
        torch.manual_seed(args.seed + ranks.rank)  # each process samples its own anchors and RoIs
    say(
        f"train {', '.join(map(str, train_set.roots))} ({len(train_set)} images)"
        + (f", val {val_set.root} ({len(val_set)} images, {val_as})" if val_set else ", no validation set")
        + f"; {sum(p.numel() for p in model.parameters()) / 1e6:.2f} M parameters; "
        f"{steps_per_epoch} steps per epoch; max size {args.max_size or 'full'}; {args.threads} threads; "
        f"device {device}; {args.workers} loader workers"
        + (
            f"; {ranks.size} processes sharing each step's {args.batch * ranks.size} images"
            if ranks.size > 1
            else ""
        ),
        flush=True,
    )
    data = TrainingImages(train_set, args.max_size, args.min_area, aug, args.seed)
    probe = pace_probe_step(steps_per_epoch) if args.time_budget_min is not None else 0
    t_start = time.perf_counter()
    steps_done = 0
    epoch = start_epoch
    while epoch < epochs:
        # The order depends only on (seed, epoch), the augmentation on (seed, epoch, image).
        order = np.random.default_rng([args.seed, epoch]).permutation(len(train_set)).tolist()
        data.epoch = epoch
        loader = torch.utils.data.DataLoader(
            data,
            batch_sampler=ranks.batches(order, args.batch),
            num_workers=args.workers,
            collate_fn=as_list,
            worker_init_fn=one_thread,
            prefetch_factor=4 if args.workers else None,
        )
        t_epoch = t_window = time.perf_counter()
        window_images = 0
        epoch_losses: list[dict[str, float]] = []
        for step, batch in enumerate(loader):
            sizes = {tuple(b[0].shape[-2:]) for b in batch}
            if len(sizes) > 1:
                raise InputError(
                    f"{', '.join(map(str, train_set.roots))}: images of different sizes "
                    f"{sorted(sizes)} in the training sets"
                )
            global_step = epoch * steps_per_epoch + step
            for group in optimizer.param_groups:
                group["lr"] = learning_rate(global_step, total_steps, args.lr)
            images = torch.stack([b[0] for b in batch]).to(device)
            targets = [{k: v.to(device) for k, v in b[1].items()} for b in batch]
            losses = ranks.mean(
                train_step(
                    model, optimizer, images, targets, before_step=lambda: ranks.average_gradients(model)
                )
            )
            if not math.isfinite(losses["total"]):
                say(
                    f"error: loss is {losses['total']} at epoch {epoch + 1} step {step + 1}; "
                    "try a lower --lr",
                    file=sys.stderr,
                )
                return 1
            step_losses.append(losses)
            epoch_losses.append(losses)
            steps_done += 1
            if steps_done == probe:
                pace = (time.perf_counter() - t_start) / steps_done * steps_per_epoch
                # The leader's clock decides, so that every process trains the same epochs.
                budget_s = args.time_budget_min * 60.0
                fit = ranks.from_leader(epochs_at_pace(budget_s, pace, start_epoch, epochs))
                if fit < epochs:
                    how = f" (from the first {steps_done} steps)"
                    say(_budget_line(args.time_budget_min, fit, epochs, how), flush=True)
                    epochs, total_steps = fit, fit * steps_per_epoch
            window_images += len(batch) * ranks.size
            if (step + 1) % args.log_every == 0 or step + 1 == steps_per_epoch:
                now = time.perf_counter()
                rate = window_images / max(now - t_window, 1e-9)
                left = (now - t_start) / steps_done * (total_steps - global_step - 1)
                terms = " ".join(f"{SHORT[k]} {losses[k]:.3f}" for k in loss_keys)
                say(
                    f"epoch {epoch + 1}/{epochs} step {step + 1}/{steps_per_epoch} | "
                    f"{rate:.2f} img/s | {terms} total {losses['total']:.3f} | "
                    f"lr {optimizer.param_groups[0]['lr']:.1e} | ETA {_duration(left)}",
                    flush=True,
                )
                t_window, window_images = now, 0
        if not ranks.replicas_agree(model):
            say(f"error: the {ranks.size} processes' weights differ after epoch {epoch + 1}", file=sys.stderr)
            return 1
        record: dict[str, Any] = {
            "epoch": epoch + 1,
            "train_losses": {k: float(np.mean([s[k] for s in epoch_losses])) for k in (*loss_keys, "total")},
            "train_seconds": time.perf_counter() - t_epoch,
            "val_map": None,
            "val_ap50": {},
        }
        improved = True
        if val_set is not None and ranks.leader:
            result = evaluate(model, val_set, args.max_size, args.val_limit, node)
            record.update(
                val_map=result["map"],
                val_ap50=result["per_class"],
                val_as=val_as,
                val_seconds_per_image=result["seconds_per_image"],
            )
            improved = result["map"] > best_map
            say(
                f"epoch {epoch + 1}/{epochs} val {format_ap(result, cfg.classes)} | "
                f"{result['seconds_per_image'] * 1e3:.0f} ms/image | train loss "
                f"{record['train_losses']['total']:.3f}" + (" | best so far" if improved else ""),
                flush=True,
            )
        history.append(record)
        seconds = seconds_before + time.perf_counter() - t_start
        if improved and ranks.leader:
            best_map = record["val_map"] if record["val_map"] is not None else best_map
            figures = {
                "epochs": epoch + 1,
                "best_epoch": epoch + 1,
                "images": len(train_set),
                "val_images": len(val_set) if val_set else 0,
                "train": [str(root) for root in train_set.roots],
                "train_recipes": [images.recipe for images in train_set.sets],
                "val": str(val_set.root) if val_set else None,
                "val_as": val_as,
                "final_losses": record["train_losses"],
                "val_map": record["val_map"],
                "val_ap50": record["val_ap50"],
                "seconds": round(seconds, 1),
                "batch": args.batch,
                "processes": ranks.size,
                "lr": args.lr,
                "seed": args.seed,
                "min_area": args.min_area,
                "device": str(device),
                "augment": asdict(aug),
                "history": history,
            }
            save_weights(model, out, KIND, VERSION, cfg.classes, settings, {"figures": figures})
            say(f"saved {out} (epoch {epoch + 1})", flush=True)
        if ranks.leader:
            _save_checkpoint(
                paths["checkpoint"],
                {
                    "kind": f"{KIND}_checkpoint",
                    "classes": list(cfg.classes),
                    "settings": settings,
                    "epoch": epoch + 1,
                    "model": model.state_dict(),
                    "optimizer": optimizer.state_dict(),
                    "torch_rng": torch.get_rng_state(),
                    "history": history,
                    "step_losses": step_losses,
                    "best_map": best_map,
                    "seconds": seconds,
                },
            )
            plot_curves(paths["curves"], step_losses, history, cfg.classes)
        epoch += 1
        if args.time_budget_min is not None:
            # The leader's clock decides, so that every process trains the same epochs.
            fit = ranks.from_leader(
                epochs_within(
                    args.time_budget_min * 60.0,
                    time.perf_counter() - t_start,
                    epoch - start_epoch,
                    epoch,
                    epochs,
                )
            )
            if fit < epochs:
                say(_budget_line(args.time_budget_min, fit, epochs), flush=True)
                epochs, total_steps = fit, fit * steps_per_epoch
    if not ranks.leader:
        return 0
    if not out.is_file():
        raise InputError(f"{out}: no weights written (no epoch was trained)")
    best, _ = load_mask_rcnn(out, cfg.classes)  # the saved file, checked as the node will load it
    plot_samples(paths["samples"], best, val_set or train_set, args.max_size)
    plot_curves(paths["curves"], step_losses, history, cfg.classes)
    print(
        f"wrote {out}, {paths['checkpoint']}, {paths['curves']}, {paths['samples']} in "
        f"{_duration(time.perf_counter() - t_start)}",
        flush=True,
    )
    return 0
