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
NOTEBOOK_BUDGET_S = 60.0
REPORT_RE = re.compile(r"^\[( |x|!)\] (\w+):", re.MULTILINE)


def need(path: Path) -> Path:
    """``path`` if it exists; otherwise skip (or FAIL under CI, any spelling: nothing may go missing there)."""
    if not path.exists():
        msg = f"{path.relative_to(ROOT)} does not exist yet"
        if in_ci():
            pytest.fail(msg)
        pytest.skip(msg)
    return path


def execute(nb: nbformat.NotebookNode, timeout: int = 120) -> tuple[nbformat.NotebookNode, float]:
    """Run a notebook top to bottom in the repo root with nbclient; errors stay in the cells."""
    from nbclient import NotebookClient

    client = NotebookClient(nb, timeout=timeout, kernel_name="python3", allow_errors=True,
                            resources={"metadata": {"path": str(ROOT)}})
    t0 = time.perf_counter()
    client.execute()
    return nb, time.perf_counter() - t0


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
