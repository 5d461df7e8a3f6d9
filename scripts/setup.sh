#!/usr/bin/env bash
# Install the kit into ./.venv (idempotent). Usage: bash scripts/setup.sh [--test]
#   --test  also install what the test suite needs (pytest, nbval, ...; ROS 1 tools and mrcal from Debian)
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
# pip lists every package on a first install (minutes); later runs only check, quietly
QUIET=""
if .venv/bin/python -c 'import dtscal_lib' 2>/dev/null; then QUIET="--quiet"; fi
echo "setup: updating pip" >&2
.venv/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip
if [ "${1:-}" = "--test" ]; then
  echo "setup: installing the kit and its test tools into .venv (pip lists each package)" >&2
  .venv/bin/python -m pip install --disable-pip-version-check --progress-bar on $QUIET -e ".[test]"
  echo "setup: ROS 1 tools" >&2
  bash scripts/install-ros.sh
  echo "setup: mrcal, the peer the benchmarks and tests measure the calibration against" >&2
  bash scripts/install-mrcal.sh
  echo "setup: the browser for the UI tests" >&2
  bash scripts/install-browser.sh
  echo "setup: JupyterHub's proxy (npm, into .hub/) for the hub test" >&2
  bash scripts/install-hub.sh
  echo "setup: bubblewrap, the sandbox dtscal grade runs student code in" >&2
  bash scripts/install-sandbox.sh
else
  echo "setup: installing the kit into .venv (pip lists each package)" >&2
  .venv/bin/python -m pip install --disable-pip-version-check --progress-bar on $QUIET -e .
  if ! command -v bwrap >/dev/null 2>&1; then
    echo "setup: to grade (dtscal grade), also run scripts/install-sandbox.sh (as root or with sudo): it installs" >&2
    echo "       bubblewrap, the sandbox student code runs in (without it the grader holds fewer barriers and says so)" >&2
  fi
fi
echo "setup: done" >&2
