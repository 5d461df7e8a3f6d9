#!/usr/bin/env bash
# Install everything the tests need, then run them all: unit and integration tests, the
# slow end-to-end tests (real ROS master, rosbag play, student notebooks), and the solution
# notebooks under nbval with their stored outputs compared, the docstring examples of dtscal_lib, and
# the lint (ruff).
# Extra arguments go to pytest, e.g. a quick local run:  bash scripts/test.sh -m "not slow"
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --test
echo "ruff check ." >&2
.venv/bin/ruff check .          # lint (config in pyproject.toml); any finding fails the run
exec .venv/bin/python -m pytest tests solutions --doctest-modules dtscal_lib --nbval --nbval-current-env \
     --nbval-sanitize-with solutions/nbval_sanitize.cfg "$@"
