#!/usr/bin/env bash
# Run the test suite: creates ./.venv (or $LASHSCOPE_VENV) on first use and installs the project.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${LASHSCOPE_VENV:-.venv}"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --disable-pip-version-check -e ".[dev]"
set +e
"$VENV/bin/python" -m pytest "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
  echo "test.sh: pytest collected no tests -- treating as failure" >&2
  exit 1
fi
exit "$rc"
