"""Benchmark: how long each course notebook takes to run top to bottom, as a student runs it.

The tests (``tests/test_notebooks.py``) check what the notebooks print, never how long they take; the
time is measured here. For each notebook of the course: the untouched student notebook, and the
student notebook with the solutions pasted in (what ``test_pasted_solutions_pass_every_check`` runs).
Baseline, in the same run: an empty notebook (kernel start and shut-down only); the ratio says what
the notebook's own cells cost on this machine, whatever its load. Target (the former test budget):
each notebook < 60 s on 2 quiet cores.

Run::

    .venv/bin/python benchmarks/bench_notebooks.py [--quick] [--json] [--check]

``--quick``: notebooks 01 and 02 only.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COURSE = ("01_pinhole_projection", "02_homography", "03_intrinsic_calibration", "03b_calibration_quality",
          "04_distortion_rectification", "05_extrinsic_calibration", "06_duckiebot_camera")
TARGET_S = 60.0


def run(nb) -> float:
    from nbclient import NotebookClient

    client = NotebookClient(nb, timeout=600, kernel_name="python3", allow_errors=True,
                            resources={"metadata": {"path": str(ROOT)}})
    t0 = time.perf_counter()
    client.execute()
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="notebooks 01 and 02 only")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--check", action="store_true", help=f"exit 1 when a notebook takes {TARGET_S:g} s or more")
    a = ap.parse_args(argv)
    import nbformat

    sys.path.insert(0, str(ROOT))
    from dtscal_lib.teaching.release import inject_solutions

    base = run(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("pass")]))
    rows = []
    for name in COURSE[:2] if a.quick else COURSE:
        student = nbformat.read(ROOT / "notebooks" / f"{name}.ipynb", as_version=4)
        solved = inject_solutions(nbformat.read(ROOT / "notebooks" / f"{name}.ipynb", as_version=4),
                                  nbformat.read(ROOT / "solutions" / f"{name}.ipynb", as_version=4))
        rows.append({"notebook": name, "untouched_s": run(student), "solved_s": run(solved)})
    load = os.getloadavg()[0]
    if a.json:
        print(json.dumps({"baseline_empty_s": base, "load": load, "notebooks": rows}, indent=1))
    else:
        print(f"load average {load:.1f}; baseline (empty notebook) {base:.1f} s")
        print(f"{'notebook':32} {'untouched':>10} {'solved':>10} {'solved / empty':>15}")
        for r in rows:
            print(f"{r['notebook']:32} {r['untouched_s']:9.1f}s {r['solved_s']:9.1f}s {r['solved_s'] / base:14.1f}x")
    missed = [r["notebook"] for r in rows if max(r["untouched_s"], r["solved_s"]) >= TARGET_S]
    if missed:
        print(f"over {TARGET_S:g} s: {', '.join(missed)}")
    return 1 if a.check and missed else 0


if __name__ == "__main__":
    sys.exit(main())
