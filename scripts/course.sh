#!/usr/bin/env bash
# Install the kit and open the course as a student sees it: JupyterLab on workspace/ (a copy of notebooks/),
# at notebook 01, on the bundled recorded Duckiebot session. `--instructor` opens solutions/ instead.
# Extra arguments go to `dtscal course` (e.g. --no-browser --port 8890).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if [ ! -f data/session/intrinsics.bag ]; then
  echo "the recorded session is missing; regenerating it into data/ (about a minute)" >&2
  .venv/bin/dtscal synth --out data
fi
exec .venv/bin/dtscal course "$@"
