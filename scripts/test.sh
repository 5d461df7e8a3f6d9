#!/usr/bin/env bash
# Install everything the tests need, then run them all: unit and integration tests, the
# slow end-to-end tests (real ROS master, rosbag play, student notebooks), and the solution
# notebooks under nbval with their stored outputs compared, the docstring examples of dtscal_lib, and
# the lint (ruff) and the type check (mypy, scripts/typecheck.py: never more errors than its baseline).
#
# pytest runs once, on 2 pytest-xdist workers, a file per worker at a time (tests/conftest.py orders the
# longest files first). No test measures time, so none needs the machine to itself. Extra arguments go to
# pytest, e.g. a quick local run:  bash scripts/test.sh -m "not slow"   (or one file: bash scripts/test.sh
# -k test_camera); `-n N` changes the number of workers (`-n 0`: no workers). The quick part includes
# nothing slow; the slow tests include tests/test_checkout_anywhere.py, which runs a part of the suite from
# a copy of the checkout under a 0700 folder (the suite must not depend on where it lies).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --test
echo "ruff check ." >&2
.venv/bin/ruff check .          # lint (config in pyproject.toml); any finding fails the run
echo "typecheck (mypy)" >&2
.venv/bin/python scripts/typecheck.py   # the library core, detect/, grading/: never more errors than scripts/mypy-baseline.txt
exec .venv/bin/python -m pytest tests solutions --doctest-modules dtscal_lib --nbval --nbval-current-env \
  --nbval-sanitize-with solutions/nbval_sanitize.cfg -n 2 --dist loadfile --no-loadscope-reorder "$@"
