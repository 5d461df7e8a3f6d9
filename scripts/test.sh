#!/usr/bin/env bash
# Install everything the tests need, then run them all: unit and integration tests, the
# slow end-to-end tests (real ROS master, rosbag play, student notebooks), and the solution
# notebooks under nbval with their stored outputs compared, the docstring examples of dtscal_lib, and
# the lint (ruff).
#
# pytest runs in two parts over the same collection (tests/conftest.py says which part a test is in):
#   1. every test not marked `serial`, on 2 pytest-xdist workers, a file per worker at a time;
#   2. the `serial` tests (the browser test, which measures latency), alone.
# Extra arguments go to BOTH parts, e.g. a quick local run:  bash scripts/test.sh -m "not slow"
# (or one file: bash scripts/test.sh -k test_camera). `-n N` changes the number of workers of part 1
# (`-n 0`: no workers). The exit status is non-zero if either part fails; a part that selects no test
# (pytest's exit 5) is not a failure as long as the other part ran tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --test
echo "ruff check ." >&2
.venv/bin/ruff check .          # lint (config in pyproject.toml); any finding fails the run
pytest_all=(.venv/bin/python -m pytest tests solutions --doctest-modules dtscal_lib --nbval --nbval-current-env
            --nbval-sanitize-with solutions/nbval_sanitize.cfg)
set +e
"${pytest_all[@]}" --dtscal-part parallel -n 2 --dist loadfile --no-loadscope-reorder "$@"
parallel=$?
echo "--- the serial tests, alone (part 2 of 2)" >&2
"${pytest_all[@]}" --dtscal-part serial "$@" -n 0
serial=$?
set -e
echo "pytest exit status: parallel part $parallel, serial part $serial" >&2
if [ "$parallel" -eq 5 ] && [ "$serial" -eq 5 ]; then exit 5; fi       # no test selected at all
for status in "$parallel" "$serial"; do
  if [ "$status" -ne 0 ] && [ "$status" -ne 5 ]; then exit "$status"; fi
done
exit 0
