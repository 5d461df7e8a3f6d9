"""End-to-end: every student notebook runs, reports "not implemented yet", and passes once solved.

How long a notebook takes is measured by ``benchmarks/bench_notebooks.py`` (against an empty notebook's
run in the same process), never asserted here; nbclient's per-cell timeout is only a safety net."""

from __future__ import annotations

import nbformat
import pytest

from dtscal_lib.teaching.release import inject_solutions
from nbtools import (COURSE, NOTEBOOKS, SOLUTIONS, UNGRADED_COURSE, cell_errors, execute, execute_student_once,
                     exercise_functions, need, reports, stream_text)

pytestmark = pytest.mark.slow


def _student(name):
    return nbformat.read(need(NOTEBOOKS / f"{name}.ipynb"), as_version=4)


@pytest.mark.parametrize("name", COURSE)
def test_untouched_student_notebook_runs_and_reports_not_implemented(name, notebook_runs):
    nb, _ = execute_student_once(name, notebook_runs)  # the run test_notebook_text also checks
    assert not cell_errors(nb), f"{name}: errors escaped cells: {cell_errors(nb)}"
    found = reports(nb)
    wanted = exercise_functions(nb)
    assert wanted, f"{name}: no exercise cells"
    assert {f for _, f in found} >= set(wanted), f"{name}: checks missing for {set(wanted) - {f for _, f in found}}"
    assert all(mark == " " for mark, _ in found), f"{name}: expected only 'not implemented yet', got {found}"


@pytest.mark.parametrize("name", COURSE)
def test_pasted_solutions_pass_every_check(name):
    solution = nbformat.read(need(SOLUTIONS / f"{name}.ipynb"), as_version=4)
    nb, _ = execute(inject_solutions(_student(name), solution))
    assert not cell_errors(nb), f"{name}: errors escaped cells: {cell_errors(nb)}"
    found = reports(nb)
    wanted = exercise_functions(nb)
    assert {f for _, f in found} >= set(wanted), f"{name}: checks missing for {set(wanted) - {f for _, f in found}}"
    assert all(mark == "x" for mark, _ in found), f"{name}: not every check passed: {found}"


@pytest.mark.parametrize("name", UNGRADED_COURSE)
def test_ungraded_notebook_runs_untouched_on_the_stand_ins(name, notebook_runs):
    """03b has no exercise: handed out untouched (no solved 03 beside it) it runs to the end on the stand-ins."""
    nb, _ = execute_student_once(name, notebook_runs)
    assert not cell_errors(nb), f"{name}: errors escaped cells: {cell_errors(nb)}"
    assert not exercise_functions(nb)
    # its only checks are the student's own practice functions, handed out as stubs
    checked = reports(nb)
    assert {f for _, f in checked} == {"per_view_rms", "worst_views", "coverage"} and all(m == " " for m, _ in checked)
    text = "".join(stream_text(c) for c in nb.cells if c.cell_type == "code")
    for func in ("intrinsics_from_homographies", "extrinsics_from_homography"):
        assert f"your `{func}` is not available" in text, func
    assert text.count("[predict]") >= 3


def test_03b_uses_the_students_notebook_03_functions_from_the_same_folder(tmp_path):
    """In the student's workspace 03b reads 03's functions (course.notebook_function): a solved 03 is used,
    an untouched one is not (its stubs fail their self-checks, and the stand-ins say so)."""
    import shutil

    ws = tmp_path / "workspace"
    ws.mkdir()
    student03 = nbformat.read(need(NOTEBOOKS / "03_intrinsic_calibration.ipynb"), as_version=4)
    solution03 = nbformat.read(need(SOLUTIONS / "03_intrinsic_calibration.ipynb"), as_version=4)
    nbformat.write(inject_solutions(student03, solution03), ws / "03_intrinsic_calibration.ipynb")
    shutil.copy(need(NOTEBOOKS / "03b_calibration_quality.ipynb"), ws / "03b_calibration_quality.ipynb")
    nb, _ = execute(nbformat.read(ws / "03b_calibration_quality.ipynb", as_version=4), cwd=ws)
    assert not cell_errors(nb), cell_errors(nb)
    text = "".join(stream_text(c) for c in nb.cells if c.cell_type == "code")
    assert "using your `intrinsics_from_homographies`" in text and "using your `extrinsics_from_homography`" in text
    assert "!! -> using" not in text  # no stand-in anywhere
    nbformat.write(student03, ws / "03_intrinsic_calibration.ipynb")  # the stubs as handed out
    nb, _ = execute(nbformat.read(ws / "03b_calibration_quality.ipynb", as_version=4), cwd=ws)
    text = "".join(stream_text(c) for c in nb.cells if c.cell_type == "code")
    assert not cell_errors(nb) and "`intrinsics_from_homographies` is not implemented yet" in text
