"""The Gradescope autograder zip: ``dtscal grade --gradescope-bundle OUT.zip``.

Gradescope unpacks the zip into ``/autograder/source``, runs ``setup.sh`` once when the
image is built, then ``run_autograder`` for every submission: the student's files are in
``/autograder/submission`` and the grades go to ``/autograder/results/results.json``.
Everything in the submission folder is that one student's (``dtscal grade --one-student``):
notebooks, ``.py`` files, and the zip ``dtscal handin`` wrote, read as it is with the caps of
:mod:`.archive` (never unpacked to disk).

The zip holds the kit's library, the hidden cases (``grading/``) and the solution notebooks
(references). ``setup.sh`` installs the library into a virtual environment and makes
``grading/`` and ``solutions/`` readable by root only, and installs bubblewrap: student code runs
in a bubblewrap sandbox that holds neither, or, where Gradescope's container allows no user
namespace, as a bare process whose barriers ``results.json`` lists (docs/grading-sandbox.md:
Gradescope's own per-submission container keeps other students out either way). ``run_autograder``
writes a results file for every submission the grader could grade (one without a course notebook
too: 0 with what to upload); when the grader itself failed (``dtscal grade`` exit status 3, or a
traceback) it withholds ``results.json`` (kept as ``results/not-graded.json``), which Gradescope
shows as an autograder failure, never as the student's 0.
For a local test, ``DTSCAL_AUTOGRADER_ROOT`` replaces ``/autograder`` and ``DTSCAL_PYTHON``
the virtual environment's Python.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

from .. import safe_write
from ..errors import DtscalError
from .material import find_material

#: the Gradescope base image to choose (its python3 is 3.12); the default Ubuntu 22.04 has 3.10
BASE_IMAGE = "Ubuntu 24.04"
SETUP_SH = """#!/usr/bin/env bash
# Gradescope runs this once, as root, when it builds the autograder image.
# The kit needs Python 3.11 or newer: choose the base image "Ubuntu 24.04" (python3 is 3.12) in the
# autograder settings; the default Ubuntu 22.04 has 3.10.
set -euo pipefail
SRC="$(cd "$(dirname "$0")" && pwd)"
AUTOGRADER="${DTSCAL_AUTOGRADER_ROOT:-/autograder}"
export DEBIAN_FRONTEND=noninteractive
echo "setup.sh: installing python3 with apt" >&2
apt-get update -qq
apt-get install -y -qq python3 python3-venv python3-pip bubblewrap >/dev/null  # bubblewrap: the sandbox
PY=""
for candidate in python3.13 python3.12 python3.11 python3; do
  if command -v "$candidate" >/dev/null 2>&1 && \\
     "$candidate" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' 2>/dev/null; then
    PY="$candidate"; break
  fi
done
if [ -z "$PY" ]; then
  echo "setup.sh: the calibration kit needs Python 3.11 or newer, but this image has $(python3 --version 2>&1)." \\
       "In the assignment's Configure Autograder page choose the base image Ubuntu 24.04, then rebuild." >&2
  exit 1
fi
echo "setup.sh: installing the kit with $($PY --version) into $AUTOGRADER/venv" >&2
"$PY" -m venv "$AUTOGRADER/venv"
"$AUTOGRADER/venv/bin/pip" install --quiet --upgrade pip
"$AUTOGRADER/venv/bin/pip" install --progress-bar off "$SRC"
# the hidden cases and the references: readable by root (the grader) only
chmod -R go-rwx "$SRC/grading" "$SRC/solutions"
echo "setup.sh: done" >&2
"""

RUN_AUTOGRADER = """#!/usr/bin/env bash
# Gradescope runs this for every submission. It leaves a results.json unless the grader itself failed.
ROOT="${{DTSCAL_AUTOGRADER_ROOT:-/autograder}}"
PY="${{DTSCAL_PYTHON:-$ROOT/venv/bin/python}}"
RESULTS="$ROOT/results/results.json"
mkdir -p "$ROOT/results"
rm -f "$RESULTS"
# everything in submission/ is this one student's: notebooks, .py files, and a `dtscal handin` zip as it is
# (read with size caps, never unpacked to disk whole)
"$PY" -m dtscal_lib.cli grade "$ROOT/submission" --one-student submission --material "$ROOT/source" \\
    --json "$RESULTS" {assignment}-q \\
    > "$ROOT/results/grade.log" 2>&1
status=$?
if [ "$status" -eq 3 ] || grep -q -e '^Traceback' -e 'not grading: bubblewrap' "$ROOT/results/grade.log"; then
  # the grader failed (or refused: no bubblewrap in this image), not the student's code: no grade at all.
  # Without results.json Gradescope shows
  # "The autograder failed to execute correctly" (never a 0); the instructor reruns the submission.
  [ -f "$RESULTS" ] && mv "$RESULTS" "$ROOT/results/not-graded.json"
  echo "not graded: grader error, rerun (the grader failed, not the student's code): results/grade.log" >&2
  cat "$ROOT/results/grade.log" >&2
  exit 1
fi
if [ ! -s "$RESULTS" ]; then
  "$PY" - "$RESULTS" "$ROOT/results/grade.log" <<'EOF'
import json, sys
log = open(sys.argv[2], errors="replace").read()[-1500:]
msg = ("The autograder could not grade this submission. Upload your notebook(s) under their course names "
       "(for example 01_pinhole_projection.ipynb).\\n" + log)
json.dump({{"score": 0, "output": msg, "tests": []}}, open(sys.argv[1], "w"))
EOF
fi
exit 0
"""

#: what the bundle holds of the kit, besides the two scripts
TREES = ("dtscal_lib", "grading")
FILES = ("pyproject.toml", "README.md", "LICENSE")


def write_bundle(out_zip, material_root=None, assignment: str | None = None, unconfined: bool = False) -> Path:
    """Write the Gradescope autograder zip; returns its path.

    Parameters
    ----------
    out_zip : path of the zip to write
    material_root : the kit with ``grading/`` and ``solutions/`` (default: this kit)
    assignment : grade every upload as this assignment (default: from the file names)
    unconfined : grade even where Gradescope's image cannot run bubblewrap (the instructor's
        ``--let-student-code-read-my-files``, passed on to every run); without it such a run is an
        autograder failure whose log says why bubblewrap fails
    """
    root = find_material(material_root)
    out = Path(out_zip)
    if out.suffix != ".zip":
        raise DtscalError(f"{out} should end in .zip (Gradescope takes a zip file)")
    out.parent.mkdir(parents=True, exist_ok=True)
    from .preflight import UNCONFINED

    flag = (f"--assignment {assignment} " if assignment else "") + (f"{UNCONFINED} " if unconfined else "")
    with safe_write.output(out, what="Gradescope bundle", suffix=".part") as tmp, \
            zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        _add_text(z, "setup.sh", SETUP_SH)
        _add_text(z, "run_autograder", RUN_AUTOGRADER.format(assignment=flag))
        for tree in TREES:
            for p in sorted((root / tree).rglob("*")):
                rel = p.relative_to(root)
                if p.is_file() and "__pycache__" not in rel.parts and p.suffix not in (".pyc", ".pyo"):
                    z.write(p, rel.as_posix())
        for nb in sorted((root / "solutions").glob("*.ipynb")):
            z.write(nb, f"solutions/{nb.name}")
        for f in FILES:
            if (root / f).is_file():
                z.write(root / f, f)
    return out


def _add_text(z: zipfile.ZipFile, name: str, text: str) -> None:
    info = zipfile.ZipInfo(name)
    info.external_attr = 0o755 << 16
    info.compress_type = zipfile.ZIP_DEFLATED
    z.writestr(info, text)
