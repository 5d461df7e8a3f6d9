"""Students write code in every notebook (issue 29): the lines they write, per notebook, printed; none at 0.

A line a student writes is a non-blank line of a solution region (what the student version replaces with a stub),
in a graded ``exercise`` cell or an ungraded ``practice`` cell. A practice function has its self-check in a later
cell and an experiment that uses it only once it passes, so the notebook runs to the end before it is written.
"""

from __future__ import annotations

import nbformat
import pytest

from dtscal_lib.teaching import release
from nbtools import SOLUTIONS

NOTEBOOKS = ["01_pinhole_projection.ipynb", "02_homography.ipynb", "03_intrinsic_calibration.ipynb",
             "03b_calibration_quality.ipynb", "04_distortion_rectification.ipynb", "05_extrinsic_calibration.ipynb",
             "06_duckiebot_camera.ipynb"]


def _written(nb, tags) -> dict[str, int]:
    lines = {}
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "code" and any(t in cell.metadata.get("tags", []) for t in tags):
            for func, body in release.region_code(cell.source, f"cell {i}").items():
                lines[func] = lines.get(func, 0) + sum(1 for line in body if line.strip())
    return lines


def test_every_notebook_has_lines_the_student_writes(capsys):
    table = {}
    for name in NOTEBOOKS:
        nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
        table[name] = (sum(_written(nb, [release.EXERCISE_TAG]).values()),
                       sum(_written(nb, [release.PRACTICE_TAG]).values()))
    with capsys.disabled():
        print("\nlines a student writes (graded exercises + own practice functions):")
        for name, (graded, practice) in table.items():
            print(f"  {name:36s} {graded:3d} + {practice:3d} = {graded + practice:3d}")
        print(f"  {'all':36s} {sum(g + p for g, p in table.values()):15d}")
    assert all(g + p > 0 for g, p in table.values()), table
    assert all(p > 0 for name, (g, p) in table.items() if name.startswith(("01", "03b", "06"))), table


@pytest.mark.parametrize("name", ["01_pinhole_projection.ipynb", "03b_calibration_quality.ipynb",
                                  "06_duckiebot_camera.ipynb"])
def test_practice_functions_are_stubbed_checked_and_used_only_once_they_pass(name):
    nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
    student = release.student_notebook(nb, name)
    practice = [i for i, c in enumerate(student.cells) if release.PRACTICE_TAG in c.metadata.get("tags", [])]
    assert practice, f"{name} has no practice cell"
    for i in practice:
        funcs = release._defined_functions(nb.cells[[c.get("id") for c in nb.cells].index(student.cells[i].id)].source)
        assert student.cells[i].source.count("raise NotImplementedError") == len(funcs)
        later = "\n".join(c.source for c in student.cells[i + 1:] if c.cell_type == "code")
        for f in funcs:
            assert f"check_{f}({f})" in later, f"{name}: {f} has no self-check"
        assert ".passed" in later, f"{name}: the experiment runs the practice functions before they pass"
    graded = release.solution_functions(SOLUTIONS / name) if any(
        release.EXERCISE_TAG in c.metadata.get("tags", []) for c in nb.cells) else {}
    assert not set(graded) & set(_written(nb, [release.PRACTICE_TAG])), "a practice function is graded"


def test_practice_checks_never_raise_even_when_nbval_grades_strictly(monkeypatch, capsys):
    """nbval with DTSCAL_STRICT=1 is an autograder (test_grading_nbval): it must not fail a notebook whose exercises
    pass because a practice function is not written."""
    from dtscal_lib.teaching.selfcheck import practice

    monkeypatch.setenv("DTSCAL_STRICT", "1")

    def stub(*args, **kwargs):
        raise NotImplementedError

    for check in (practice.check_picture_difference, practice.check_tilt_needed, practice.check_per_view_rms,
                  practice.check_worst_views, practice.check_coverage, practice.check_next_board_move):
        assert check(stub).status == "not implemented yet"
        assert not check(lambda *a, **k: 0).passed  # wrong, and still no exception
