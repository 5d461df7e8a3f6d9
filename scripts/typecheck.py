#!/usr/bin/env python3
"""Type check of the library core, detection and grading (mypy), never growing past its baseline.

Checked: ``dtscal_lib/*.py`` (the core: camera, calibration, the judge, the files, the session), ``dtscal_lib/detect/``
and ``dtscal_lib/grading/`` (settings in pyproject.toml's ``[tool.mypy]``). The errors are counted per file and in
all; ``scripts/mypy-baseline.txt`` holds the count of the day the check was added (issue 31: 177 errors
reported then over the library; see the file for this selection's). The check fails when the total grows,
printing the new errors of the files whose count grew; it says so when the total fell, so the baseline can
be lowered (``--update`` writes it).

Run::

    .venv/bin/python scripts/typecheck.py            # what scripts/test.sh runs
    .venv/bin/python scripts/typecheck.py --update   # write the baseline (only ever lower it)
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "scripts" / "mypy-baseline.txt"
TARGETS = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "dtscal_lib").glob("*.py")) + [
    "dtscal_lib/detect", "dtscal_lib/grading"]
ERROR = re.compile(r"^(?P<file>[^:]+):\d+(?::\d+)?: error: ")


def run_mypy() -> list[str]:
    proc = subprocess.run([sys.executable, "-m", "mypy", "--no-error-summary", "--hide-error-context",
                           "--no-color-output", *TARGETS], cwd=ROOT, capture_output=True, text=True, check=False)
    if proc.returncode not in (0, 1) or "error: " not in proc.stdout and proc.returncode == 1:
        sys.exit(f"typecheck: mypy did not run ({proc.returncode}): {proc.stderr or proc.stdout}")
    return [line for line in proc.stdout.splitlines() if ERROR.match(line)]


def read_baseline() -> tuple[int, Counter]:
    total, per_file = None, Counter()
    for line in BASELINE.read_text(encoding="utf-8").splitlines():
        if line.startswith("#") or not line.strip():
            continue
        name, count = line.rsplit(None, 1)
        if name == "total":
            total = int(count)
        else:
            per_file[name] = int(count)
    if total is None:
        sys.exit(f"typecheck: {BASELINE} has no 'total N' line")
    return total, per_file


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--update", action="store_true", help="write the baseline from this run")
    args = ap.parse_args()
    errors = run_mypy()
    per_file = Counter(ERROR.match(e)["file"] for e in errors)
    if args.update:
        lines = ["# mypy errors in the library core, detect/ and grading/ (scripts/typecheck.py); never more",
                 f"total {len(errors)}"] + [f"{f} {n}" for f, n in sorted(per_file.items())]
        BASELINE.write_text("\n".join(lines) + "\n", encoding="utf-8")
        print(f"typecheck: baseline written: {len(errors)} errors")
        return 0
    total, before = read_baseline()
    if len(errors) > total:
        grown = {f for f, n in per_file.items() if n > before.get(f, 0)}
        print(f"typecheck: {len(errors)} mypy errors, more than the baseline's {total} ({BASELINE.name}); new in "
              f"{', '.join(sorted(grown)) or 'files moved'}:", file=sys.stderr)
        for e in errors:
            if ERROR.match(e)["file"] in grown:
                print(f"  {e}", file=sys.stderr)
        return 1
    note = f" (below the baseline's {total}: lower it with --update)" if len(errors) < total else ""
    print(f"typecheck: {len(errors)} mypy errors{note}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
