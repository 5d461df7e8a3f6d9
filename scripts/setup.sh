#!/usr/bin/env bash
# Install the kit into ./.venv (idempotent). Usage: bash scripts/setup.sh [--test]
#   --test  also install what the test suite needs (pytest, nbval, ...; ROS 1 tools from Debian)
set -euo pipefail
cd "$(dirname "$0")/.."

pick_python() {
  for py in "${PYTHON:-}" python3 python3.12 python3.11; do
    [ -n "$py" ] || continue
    command -v "$py" >/dev/null 2>&1 || continue
    if "$py" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' 2>/dev/null; then
      echo "$py"; return 0
    fi
  done
  echo "dtscal needs Python >= 3.11; install it or set PYTHON=/path/to/python3.11" >&2
  return 1
}

if [ ! -x .venv/bin/python ]; then
  py=$(pick_python)
  echo "creating .venv with $($py --version)" >&2
  "$py" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip
if [ "${1:-}" = "--test" ]; then
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -e ".[test]"
  bash scripts/install-ros.sh
  bash scripts/install-browser.sh
else
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -e .
fi
