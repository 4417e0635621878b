#!/usr/bin/env bash
# Set up on a fresh machine and run the main job on the embedded default:
# creates ./.venv, installs lashscope, and runs `lashscope demo` (SQLite + files in ./lashscope-data).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${LASHSCOPE_VENV:-.venv}"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --disable-pip-version-check -e .
exec "$VENV/bin/lashscope" demo "$@"
