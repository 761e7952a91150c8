#!/usr/bin/env bash
# Sets up whatever is missing, then lints and runs the whole test suite (extra arguments go to pytest).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
VENV="${TLT_VENV:-$ROOT/.venv}"
cd "$ROOT"
echo "[test] ruff check"
"$VENV/bin/ruff" check --quiet $(ls -d src sim tests bench 2>/dev/null)
echo "[test] pytest"
exec "$VENV/bin/python" -m pytest "$@"
