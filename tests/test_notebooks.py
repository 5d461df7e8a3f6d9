"""End-to-end: every student notebook runs, reports "not implemented yet", and passes once solved.

How long a notebook takes is measured by ``benchmarks/bench_notebooks.py`` (against an empty notebook's
run in the same process), never asserted here; nbclient's per-cell timeout is only a safety net."""

from __future__ import annotations

import nbformat
import pytest

from dtscal_lib.teaching.release import inject_solutions
from nbtools import (COURSE, NOTEBOOKS, SOLUTIONS, cell_errors, execute, execute_student_once,
                     exercise_functions, need, reports)

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
