"""Helpers shared by the course-notebook tests (test_release, test_notebooks, test_solutions_vs_opencv)."""

from __future__ import annotations

import re
import time
from pathlib import Path

import nbformat
import pytest
from ci import in_ci

ROOT = Path(__file__).resolve().parent.parent
SOLUTIONS = ROOT / "solutions"
NOTEBOOKS = ROOT / "notebooks"
#: every course notebook; 03-05 are written by another helper and tested as soon as they exist
COURSE = ("01_pinhole_projection", "02_homography", "03_intrinsic_calibration",
          "04_distortion_rectification", "05_extrinsic_calibration")
#: course notebooks with predictions and experiments but no exercise function (not graded; 06 has its own tests)
UNGRADED_COURSE = ("03b_calibration_quality",)
REPORT_RE = re.compile(r"^\[( |x|!)\] (\w+):", re.MULTILINE)


def need(path: Path) -> Path:
    """``path`` if it exists; otherwise skip (or FAIL under CI, any spelling: nothing may go missing there)."""
    if not path.exists():
        msg = f"{path.relative_to(ROOT)} does not exist yet"
        if in_ci():
            pytest.fail(msg)
        pytest.skip(msg)
    return path


def execute(nb: nbformat.NotebookNode, timeout: int = 120, cwd: Path = ROOT) -> tuple[nbformat.NotebookNode, float]:
    """Run a notebook top to bottom in ``cwd`` (default the repo root) with nbclient; errors stay in the cells.

    Returns ``(nb, seconds)``; the seconds are for benchmarks/bench_notebooks.py, no test asserts them.
    ``timeout`` (per cell) is a safety net, about 10x the slowest cell."""
    from nbclient import NotebookClient

    client = NotebookClient(nb, timeout=timeout, kernel_name="python3", allow_errors=True,
                            resources={"metadata": {"path": str(cwd)}})
    t0 = time.perf_counter()
    client.execute()
    return nb, time.perf_counter() - t0


def execute_student_once(name: str, cache: Path, timeout: int = 300) -> tuple[nbformat.NotebookNode, float]:
    """The generated student notebook ``name`` run as handed out (untouched), once per test run: ``(nb, seconds)``.

    Two tests check that same run (test_notebooks: it ends, says "not implemented yet", within the budget;
    test_notebook_text: the prose holds on the stand-in path). The first to ask runs it with :func:`execute` and
    stores it in ``cache`` (a folder shared by the run's xdist workers; a lock keeps a second worker waiting
    rather than running it again); the others read it back. A run that raised is not stored.
    """
    import fcntl
    import hashlib
    import json

    src = need(NOTEBOOKS / f"{name}.ipynb")
    stem = f"{name}-{hashlib.sha256(src.read_bytes()).hexdigest()[:16]}"
    cache.mkdir(parents=True, exist_ok=True)
    done, meta = cache / f"{stem}.ipynb", cache / f"{stem}.json"
    with open(cache / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not meta.exists():
            nb, seconds = execute(nbformat.read(src, as_version=4), timeout=timeout)
            nbformat.write(nb, done)
            meta.write_text(json.dumps({"seconds": seconds}))
    return nbformat.read(done, as_version=4), json.loads(meta.read_text())["seconds"]


def cell_errors(nb) -> list[str]:
    """``"cell i: Ename: message"`` for every error output."""
    return [f"cell {i}: {o.ename}: {o.evalue}" for i, c in enumerate(nb.cells) if c.cell_type == "code"
            for o in c.get("outputs", []) if o.output_type == "error"]


def stream_text(cell) -> str:
    return "".join(o.get("text", "") for o in cell.get("outputs", []) if o.output_type == "stream")


def reports(nb) -> list[tuple[str, str]]:
    """Self-check report heads ``(mark, function)`` printed anywhere: mark is 'x', '!' or ' '."""
    return [(m.group(1), m.group(2)) for c in nb.cells if c.cell_type == "code"
            for m in REPORT_RE.finditer(stream_text(c))]


def exercise_functions(nb) -> list[str]:
    """Names of the functions defined in cells tagged ``exercise``."""
    import ast

    names = []
    for c in nb.cells:
        if c.cell_type == "code" and "exercise" in c.get("metadata", {}).get("tags", []):
            names += [n.name for n in ast.parse(c.source).body if isinstance(n, ast.FunctionDef)]
    return names


def checks_of(assignment: str) -> int:
    """How many hidden checks grade ``assignment`` (grading/cases.py: one Gradescope test each)."""
    import runpy

    from dtscal_lib.exercise_rules import NOTEBOOKS

    cases = runpy.run_path(str(ROOT / "grading" / "cases.py"))["CHECKS"]
    return sum(len(cases[f]) for f in NOTEBOOKS[assignment].functions)
