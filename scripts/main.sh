#!/usr/bin/env bash
# Sets up whatever is missing, then runs the main job: the whole system on the MuJoCo twin (every
# driver node behind its real link, the CRS, ARS X, ARS Y, the MCAP recorder) supervised by the
# ground station, which sends an authenticated Start over CCSDS, shows progress, and prints the
# summary at the end (docs/system.md).
#
#   scripts/main.sh [--mission NAME] [--gui] [--real-time] [--bringup]
#     --mission NAME   missions/NAME.yaml (default two_bay)
#     --gui            the Qt ground station instead of the headless job (at real time)
#     --real-time      the twin at real time and the arms at their files' speed, to follow them;
#                      without it (and --gui) the headless job builds as fast as the machine
#                      allows: the twin uncapped, the arms at their full speed limits
#     --bringup        only the hardware layer on the twin and the bring-up check of every driver
#
# The run's files (archive, timeline plot, recording, tower model, logs) stay in $TLT_RUN_DIR.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SET=mission_twin
MISSION=two_bay
REAL_TIME=0
while [ $# -gt 0 ]; do
    case "$1" in
        --mission) MISSION="${2:?--mission needs a name}"; shift 2 ;;
        --gui) SET=mission_twin_gui; REAL_TIME=1; shift ;;
        --real-time) REAL_TIME=1; shift ;;
        --bringup) SET=bringup_twin; shift ;;
        -h|--help) sed -n 2,15p "$0"; exit 0 ;;
        *) echo "main.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
done
if [ ! -f "$ROOT/missions/$MISSION.yaml" ]; then
    echo "main.sh: no mission missions/$MISSION.yaml" >&2
    exit 2
fi
bash "$ROOT/scripts/setup.sh"
VENV="${TLT_VENV:-$ROOT/.venv}"
# Fast DDS shared-memory files that killed runs left in /dev/shm (hundreds piled up on the
# development machine): those no process holds go; a running system's stay.
[ -x "$VENV/bin/fastdds" ] && "$VENV/bin/fastdds" shm clean > /dev/null 2>&1 || true
# A private device folder, ROS domain and UR controller addresses (all of 127/8 is loopback), so
# the job does not meet another run, or pytest's emulated arms on 127.0.0.2/.3, on this machine.
export TLT_RUN_DIR="${TLT_RUN_DIR:-$(mktemp -d /tmp/tlt-run.XXXXXX)}"
UR_NET="127.0.$((100 + RANDOM % 150))"
export TLT_UR_X_HOST="${TLT_UR_X_HOST:-$UR_NET.2}" TLT_UR_Y_HOST="${TLT_UR_Y_HOST:-$UR_NET.3}"
export TLT_MISSION="$MISSION"
if [ "$REAL_TIME" = 0 ]; then
    # As fast as the machine allows; the environment's own settings win.
    export TLT_TWIN_RTF="${TLT_TWIN_RTF:-0}" TLT_ARM_VELOCITY_SCALE="${TLT_ARM_VELOCITY_SCALE:-1}"
fi
echo "main.sh: mission $MISSION, run files in $TLT_RUN_DIR"
status=0
"$VENV/bin/tlt" launch --isolated "$ROOT/config/launch/$SET.yaml" || status=$?
echo "main.sh: run files in $TLT_RUN_DIR:"
ls "$TLT_RUN_DIR"
exit "$status"
