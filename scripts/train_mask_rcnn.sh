#!/usr/bin/env bash
# Render a Mask R-CNN training set from the twin in parallel shards, then train on one device.
#
#   scripts/train_mask_rcnn.sh OUT_DIR
#
# Settings (environment): COUNT training images (6000), SHARDS render processes (nproc - 1), VAL
# validation images (80, seed 1: the validation set of models/vision/README.md), DEVICE (cuda),
# RANKS training processes on the device, each on BATCH images of every step, their gradients
# averaged (1; the per-image Python leaves a GPU mostly idle, so several fill it), WORKERS loader
# processes for each (8), THREADS torch CPU threads for each (4), BUDGET_MIN minutes of training
# (the epochs that fit; 8), EPOCHS at most (40), BATCH (8), LR (2e-3), RENDER_LIMIT_S seconds the
# shards may render before what they have is used (240), and MODEL: the trainer's options for the
# model (default the shipped model's: full-size images, 56x56 masks, anchors 16-128, the semantic
# head for tubes and frame sides; models/vision/README.md). PYTHON (python3) must import the project
# (PYTHONPATH=src:sim:tools, or the venv) with CUDA torch and MuJoCo; MUJOCO_GL=egl renders on the GPU.
# INIT: weights to start from (the trainer's --init; INIT=models/vision/mask_rcnn.pt continues the
# shipped model, so each lent machine's minutes add to the last's). SCENES: the training images'
# scene weights (render_dataset's --scenes, e.g. "held=0.2 presented=0.3 ..."; default its own).
# NOISE grey levels and BLUR pixels: the most sensor noise and blur added to a training image (the
# trainer's --sensor-noise and --blur; 0, none, as the shipped model trained).
# NODE_CONFIG (config/vision/node.yaml): validate on the masks as the vision node so configured
# makes them (the trainer's --node-config; the benchmark's figure, which picks the best epoch);
# NODE_CONFIG= validates the model's masks alone.
# SEED_BASE (1000): shard k renders with seed SEED_BASE + k; give each lending's run new seeds.
# RENDER=0 renders nothing: the run waits for another run's shards in the same DATA_DIR (its
# "rendered" marker) and trains on them, so two models can train side by side on one device.
#
# Shard k renders with seed SEED_BASE + k, so shards never repeat each other, the validation set or
# the benchmark's seeds (900, 901). A shard stopped at RENDER_LIMIT_S keeps its last whole index.
# Everything lands in OUT_DIR: mask_rcnn.pt + .json, curves, samples, train.log, render logs.
set -euo pipefail
out=${1:?usage: scripts/train_mask_rcnn.sh OUT_DIR}
cd "$(dirname "${BASH_SOURCE[0]}")/.."
PYTHON=${PYTHON:-python3}
COUNT=${COUNT:-6000}
SHARDS=${SHARDS:-$(( $(nproc) > 1 ? $(nproc) - 1 : 1 ))}
VAL=${VAL:-80}
DEVICE=${DEVICE:-cuda}
RANKS=${RANKS:-1}
WORKERS=${WORKERS:-8}
THREADS=${THREADS:-4}
BUDGET_MIN=${BUDGET_MIN:-8}
EPOCHS=${EPOCHS:-40}
BATCH=${BATCH:-8}
LR=${LR:-2e-3}
RENDER_LIMIT_S=${RENDER_LIMIT_S:-240}
RENDER=${RENDER:-1}
INIT=${INIT:-}
NOISE=${NOISE:-0}
BLUR=${BLUR:-0}
SCENES=${SCENES:-}
SEED_BASE=${SEED_BASE:-1000}
NODE_CONFIG=${NODE_CONFIG-config/vision/node.yaml}
MODEL=${MODEL:---config semantic_classes=[\"strut_tube\",\"cross_frame\"] --config mask_pool=28 --config anchor_sizes=[16,32,64,128] --config rpn_fg_iou=0.5}
data=${DATA_DIR:-/tmp/tlt-vision-data}
mkdir -p "$out" "$data"
log() { echo "[train_mask_rcnn $(date -u +%H:%M:%S)] $*"; }

smoke_train() {
    # shellcheck disable=SC2086
    "$PYTHON" -m tlt_tools.vision_training.mask_rcnn --train "$data/smoke" --val "$data/smoke" \
        --out "$out/smoke_out/w.pt" --epochs 1 --batch 1 --ranks $(( RANKS > 1 ? 2 : 1 )) \
        --device "$DEVICE" $MODEL ${NODE_CONFIG:+--node-config "$NODE_CONFIG"} > "$out/smoke.log"
    rm -rf "$out/smoke_out"
    log "smoke test passed"
}

if [ "$RENDER" = 0 ]; then
    log "waiting for the images of the run rendering into $data"
    waited=0
    until [ -f "$data/rendered" ]; do
        sleep 2
        waited=$(( waited + 2 ))
        # The rendering run's smoke test and its shards' time limit, and a margin.
        [ "$waited" -lt $(( RENDER_LIMIT_S + 300 )) ] || { log "no images in $data after ${waited} s"; exit 1; }
    done
    log "smoke test: train one step on $DEVICE"
    smoke_train
else
    rm -f "$data/rendered"
    # 1. Fail fast: two rendered images and one training step on the device.
    log "smoke test: render 2 images, train one step on $DEVICE"
    "$PYTHON" -m tlt_tools.vision_training.render_dataset --out "$data/smoke" --count 2 --seed 999 --progress-every 2
    smoke_train

    # 2. The shards and the validation set, in parallel.
    per=$(( (COUNT + SHARDS - 1) / SHARDS ))
    log "rendering $COUNT images in $SHARDS shards of $per, and $VAL validation images"
    pids=()
    for k in $(seq 0 $(( SHARDS - 1 ))); do
        timeout "$RENDER_LIMIT_S" "$PYTHON" -m tlt_tools.vision_training.render_dataset --out "$data/train_$k" \
            --count "$per" --seed $(( SEED_BASE + k )) --progress-every 50 ${SCENES:+--scenes $SCENES} \
            > "$data/render_$k.log" 2>&1 &
        pids+=($!)
    done
    timeout "$RENDER_LIMIT_S" "$PYTHON" -m tlt_tools.vision_training.render_dataset --out "$data/val" --count "$VAL" \
        --seed 1 --progress-every 20 > "$data/render_val.log" 2>&1 &
    pids+=($!)
    for pid in "${pids[@]}"; do wait "$pid" || true; done
    tail -n 2 "$data"/render_*.log > "$out/render.log" 2>/dev/null || true
    touch "$data/rendered"
fi
shards=()
for k in $(seq 0 $(( SHARDS - 1 ))); do
    [ -f "$data/train_$k/index.json" ] && shards+=("$data/train_$k")
done
[ ${#shards[@]} -gt 0 ] || { log "no shard rendered an image set"; exit 1; }
rendered=$("$PYTHON" -c "import sys; from tlt_tools.vision_training.dataset import ImageSet
print(sum(len(ImageSet(p)) for p in sys.argv[1:]))" "${shards[@]}")
log "rendered $rendered training images in ${#shards[@]} shards"

# 3. Train within the budget, validating each epoch; the best epoch's weights are kept.
log "training on $DEVICE for at most $BUDGET_MIN min"
# shellcheck disable=SC2086
"$PYTHON" -m tlt_tools.vision_training.mask_rcnn --train "${shards[@]}" --val "$data/val" --val-limit 60 \
    --out "$out/mask_rcnn.pt" --epochs "$EPOCHS" --batch "$BATCH" --lr "$LR" --device "$DEVICE" \
    --ranks "$RANKS" --workers "$WORKERS" --threads "$THREADS" --time-budget-min "$BUDGET_MIN" \
    --log-every 50 --sensor-noise "$NOISE" --blur "$BLUR" $MODEL \
    ${INIT:+--init "$INIT"} ${NODE_CONFIG:+--node-config "$NODE_CONFIG"} \
    2>&1 | tee "$out/train.log"
rm -f "$out/mask_rcnn_checkpoint.pt"  # optimiser state: large, and not what ships
log "done: $out"
