#!/usr/bin/env bash
# Install everything the tests need, then run them all: unit and integration tests, the
# slow end-to-end tests (real ROS master, rosbag play, student notebooks), and the solution
# notebooks under nbval with their stored outputs compared.
# Extra arguments go to pytest, e.g. a quick local run:  bash scripts/test.sh -m "not slow"
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --test
exec .venv/bin/python -m pytest tests solutions --nbval --nbval-current-env \
     --nbval-sanitize-with solutions/nbval_sanitize.cfg "$@"
