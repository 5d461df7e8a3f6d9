#!/usr/bin/env bash
# Install the kit and open the course as a student sees it: JupyterLab on workspace/ (a copy of notebooks/),
# at notebook 01, on the bundled recorded Duckiebot session. `--instructor` opens solutions/ instead.
# Extra arguments go to `dtscal course` (e.g. --no-browser --port 8890).
# The first run installs with the hand-out's installer (scripts/install-course.sh: uv, else pip, a line per step
# and every 5 s); later runs start at once. To update the kit's packages in .venv: bash scripts/setup.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
WHO=course.sh
source scripts/install-course.sh
course_installed || install_course
if [ ! -f data/session/intrinsics.bag ]; then
  say "the recorded session is missing; regenerating it into data/ (about a minute)"
  ticking "regenerating the recording" .venv/bin/dtscal synth --out data
fi
exec .venv/bin/dtscal course "$@"
