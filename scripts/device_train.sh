#!/usr/bin/env bash
# Continue the shipped Mask R-CNN on a lent GPU machine, by the recipe of models/vision/README.md
# ("what is next"), in as few device minutes as possible.
#
#   scripts/device_train.sh prepare      # here: fetch what the device lacks into .device/
#   scripts/device_train.sh train        # there: install it, render and train into /tmp/r, copy to $OUT
#   scripts/device_train.sh candidate    # there, the next call: bench the weights against the shipped
#
# A lent machine has CUDA torch, SciPy, OpenCV and PyYAML for its own Python (3.12), but no MuJoCo
# and no EGL loader, and reaches no network. `prepare` downloads Python 3.12 wheels of the pinned
# MuJoCo (requirements/twin.txt) and of glfw and PyOpenGL, and the Debian packages of the GL
# loaders, into .device/ (git ignores it: name it in the device call's carry, [".device"]).
# `train` unpacks them there (pip --target, dpkg -x), renders COUNT images on the GPU and trains
# from the shipped weights within the call; its settings are the README's and can be overridden in
# the environment as scripts/train_mask_rcnn.sh reads them. `candidate` runs bench/vision_candidate.py
# on the five held-out seeds and the inspection seeds for the new and the shipped weights, the table
# that decides whether the new weights ship (docs/vision.md, "Benchmark").
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
DEVICE_DIR=${DEVICE_DIR:-.device}  # where prepare leaves what the device lacks
SITE=/tmp/tlt-device-site
RUN=/tmp/r
GL_PACKAGES=(libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)

prepare() {
    local mujoco
    mujoco=$(grep -E '^mujoco==' requirements/twin.txt)
    rm -rf "$DEVICE_DIR" && mkdir -p "$DEVICE_DIR/wheels" "$DEVICE_DIR/debs"
    # No dependencies: the device's Python has numpy; mujoco's own pure-Python ones come by name.
    # mujoco 4's native library is a wheel of its own, mujoco-core, of the same version.
    python3 -m pip download -q --no-deps --only-binary :all: --python-version 3.12 \
        --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux2014_x86_64 \
        -d "$DEVICE_DIR/wheels" "$mujoco" "mujoco-core==${mujoco#mujoco==}" glfw pyopengl absl-py etils
    (cd "$DEVICE_DIR/debs" && apt-get download -q "${GL_PACKAGES[@]}" > /dev/null)
    ls -l "$DEVICE_DIR/wheels" "$DEVICE_DIR/debs"
    du -sh "$DEVICE_DIR"
}

install_on_device() {
    [ -d "$DEVICE_DIR/wheels" ] || { echo "no $DEVICE_DIR/wheels: run '$0 prepare' here and carry .device" >&2; exit 2; }
    for deb in "$DEVICE_DIR"/debs/*.deb; do dpkg -x "$deb" /; done
    ldconfig
    # The GPU's own EGL vendor file, where the machine's driver mounts it.
    local vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    [ -f "$vendor" ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target "$SITE" "$DEVICE_DIR"/wheels/*.whl
    export PYTHONPATH="$SITE:src:sim:tools" MUJOCO_GL=egl PYTHONUNBUFFERED=1
    nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
}

train() {
    : "${OUT:?train runs on the device machine, which sets OUT}"
    install_on_device
    export INIT=${INIT:-models/vision/mask_rcnn.pt} RANKS=${RANKS:-6} WORKERS=${WORKERS:-1}
    export THREADS=${THREADS:-2} BATCH=${BATCH:-4} LR=${LR:-2e-4} COUNT=${COUNT:-9600}
    export EPOCHS=${EPOCHS:-1} BUDGET_MIN=${BUDGET_MIN:-6} RENDER_LIMIT_S=${RENDER_LIMIT_S:-80}
    export SEED_BASE=${SEED_BASE:-12000} VAL=${VAL:-60}
    local status=0
    timeout "${TRAIN_LIMIT_S:-540}" scripts/train_mask_rcnn.sh "$RUN" 2>&1 | tee "$OUT/call.log" || status=$?
    # Whatever the run left, even cut short: the log says how far it got.
    for f in mask_rcnn.pt mask_rcnn.json train.log render.log mask_rcnn_curves.png; do
        [ -f "$RUN/$f" ] && cp "$RUN/$f" "$OUT/"
    done
    return "$status"
}

candidate() {
    : "${OUT:?candidate runs on the device machine, which sets OUT}"
    [ -f "$RUN/mask_rcnn.pt" ] || { echo "no $RUN/mask_rcnn.pt: run '$0 train' first on this machine" >&2; exit 2; }
    install_on_device
    python3 bench/vision_candidate.py --weights "$RUN/mask_rcnn.pt" --jobs "${JOBS:-14}" \
        --work /tmp/cand | tee "$OUT/candidate.txt"
}

case "${1:-}" in
    prepare) prepare ;;
    train) train ;;
    candidate) candidate ;;
    *) echo "usage: $0 prepare|train|candidate" >&2; exit 2 ;;
esac
