#!/usr/bin/env bash
# Sets up whatever is missing, then lints and runs the whole test suite.
#
# With no arguments the suite runs in two stages: the tests outside tests/system on
# $TLT_TEST_WORKERS pytest-xdist workers (3 by default; each test file stays on one worker, in
# order, with its module fixtures), then the system tests one at a time, since each starts the
# whole system and the nominal build takes every core it can get. Most of the first stage waits
# on the wall clock (arms moving at their real speed, links timing out), so on two cores three
# workers finish it sooner than two; tests/tlt_ars/test_ars_requests.py, one stack in file order,
# takes most of it on its own worker. Both stages run; the exit status is the first failing one's.
# With arguments, they go to one plain pytest run.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
VENV="${TLT_VENV:-$ROOT/.venv}"
cd "$ROOT"
# Fast DDS shared-memory files that killed runs left in /dev/shm (hundreds piled up on the
# development machine): those no process holds go; a running system's stay.
[ -x "$VENV/bin/fastdds" ] && "$VENV/bin/fastdds" shm clean > /dev/null 2>&1 || true
# One OpenMP thread per process unless the caller says otherwise: three workers already share two
# cores, and torch's intra-op threads (two per process here) only spin against each other and the
# other workers; with one thread each the vision and bench tests finish sooner and use less CPU.
# Code that sets its own count (the vision node's torch_threads, the trainers' --threads) still does.
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
echo "[test] ruff check, ruff format --check"
"$VENV/bin/ruff" check --quiet $(ls -d src sim tools tests bench 2>/dev/null)
"$VENV/bin/ruff" format --check --quiet $(ls -d src sim tools tests bench 2>/dev/null)
# The packages and settings are in pyproject.toml ([tool.mypy]); its cache under build/ makes a
# second run read only the files that changed.
echo "[test] mypy"
"$VENV/bin/mypy"
if [ $# -gt 0 ]; then
    echo "[test] pytest $*"
    exec "$VENV/bin/python" -m pytest "$@"
fi
status=0
echo "[test] pytest, everything but the system tests, on ${TLT_TEST_WORKERS:-3} workers"
"$VENV/bin/python" -m pytest -m "not system" -n "${TLT_TEST_WORKERS:-3}" --dist loadfile || status=$?
echo "[test] pytest, the system tests"
"$VENV/bin/python" -m pytest -m system || { s=$?; [ "$status" -ne 0 ] || status=$s; }
exit "$status"
