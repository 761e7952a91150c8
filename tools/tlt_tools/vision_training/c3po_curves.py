"""C-3PO detectors' training curves, read back from their weights' manifests, in one picture.

Each detector's manifest keeps its training history (``extra.history``: per epoch the training
loss and, where measured, the validation loss and the fraction of validation clouds whose
corrected pose is certified; :mod:`tlt_tools.vision_training.c3po_supervised`, :mod:`.c3po_self_supervised`).
This draws every given detector's certified fraction against the 95 % goal, and its losses, so
the shipped models' training can be seen without training them again::

    python -m tlt_tools.vision_training.c3po_curves models/vision/{end_fitting,corner_joint,rivet}.pt \\
        --out models/vision/c3po_curves.png
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from tlt_vision.weights import WeightsError, read_manifest

GOAL = 0.95


def histories(paths: Sequence[str | Path]) -> dict[str, list[dict]]:
    """Each weights file's name (its stem) and training history; WeightsError naming the file
    whose manifest has none."""
    out = {}
    for path in paths:
        history = read_manifest(path).get("extra", {}).get("history")
        if not isinstance(history, list) or not history or not all("epoch" in h for h in history):
            raise WeightsError(path, "manifest has no training history (extra.history, a list of epochs)")
        out[Path(path).stem] = history
    return out


def plot_curves(curves: dict[str, list[dict]], path: str | Path) -> Path:
    """Validation certified fraction and training (solid) and validation (dashed) loss by epoch,
    one line per detector, as a PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (cx, lx) = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, (name, history) in enumerate(curves.items()):
        colour = plt.get_cmap("tab10")(i % 10)
        certified = [(h["epoch"], h["val_certified"]) for h in history if h.get("val_certified") is not None]
        if certified:
            cx.plot(*zip(*certified, strict=True), marker="o", markersize=3, color=colour, label=name)
        for key, style in (("train_loss", "-"), ("val_loss", "--")):
            points = [(h["epoch"], h[key]) for h in history if h.get(key) is not None]
            if points:
                lx.plot(
                    *zip(*points, strict=True),
                    linestyle=style,
                    color=colour,
                    label=name if key == "train_loss" else None,
                )
    cx.axhline(GOAL, color="grey", linestyle=":", linewidth=1, label="goal 95 %")
    cx.set(
        xlabel="epoch",
        ylabel="validation clouds certified",
        ylim=(0, 1.02),
        title="C-3PO: corrected poses certified",
    )
    lx.set(
        xlabel="epoch",
        ylabel="keypoint loss / (half the model's size)²",
        yscale="log",
        title="loss: training (solid), validation (dashed)",
    )
    cx.legend(fontsize=8, loc="lower right")
    lx.legend(fontsize=8)
    for axis in (cx, lx):
        axis.grid(alpha=0.3)
        axis.xaxis.get_major_locator().set_params(integer=True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], prog="c3po_curves")
    p.add_argument("weights", nargs="+", type=Path, help="C-3PO detector weights (.pt, manifest beside)")
    p.add_argument("--out", required=True, type=Path, help="PNG to write")
    args = p.parse_args(argv)
    try:
        curves = histories(args.weights)
    except WeightsError as exc:
        print(f"c3po_curves: {exc}", file=sys.stderr)
        return 2
    print(f"c3po_curves: {len(curves)} detectors -> {plot_curves(curves, args.out)}")
    return 0


__all__ = ["histories", "main", "plot_curves"]

if __name__ == "__main__":
    sys.exit(main())
