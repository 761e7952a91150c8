#!/usr/bin/env bash
# Sets up whatever is missing, then runs the main job. Today that is the largest part of the
# system that runs end to end: the MuJoCo twin behind every driver's real link, every driver
# node, and the bring-up check moving each mechanism through its driver (README, "What the main
# job does today").
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
VENV="${TLT_VENV:-$ROOT/.venv}"
# A private device folder and ROS domain, so the job does not meet another run on this machine.
export TLT_RUN_DIR="${TLT_RUN_DIR:-$(mktemp -d /tmp/tlt-run.XXXXXX)}"
exec "$VENV/bin/tlt" launch --isolated "$ROOT/config/launch/bringup_twin.yaml"
