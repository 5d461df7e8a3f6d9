"""Predict-then-check (dtscal_lib.teaching.selfcheck.predict): verdicts, explanations, clear errors, and that the
grader never sees the prediction cells of the solution notebooks."""

from __future__ import annotations

import ast

import nbformat
import pytest

from dtscal_lib.teaching import release
from dtscal_lib.teaching.selfcheck import predict
from nbtools import SOLUTIONS

COURSE = ["01_pinhole_projection.ipynb", "02_homography.ipynb", "03_intrinsic_calibration.ipynb",
          "04_distortion_rectification.ipynb", "05_extrinsic_calibration.ipynb"]


def test_number_right_wrong_and_missing():
    right = predict.predict_number("q", 5.0, 5.4, atol=0.5, why="because")
    assert right.right and "right" in right.text() and "because" in right.text()
    wrong = predict.predict_number("q", 5.0, 6.0, atol=0.5, unit="px", why="because")
    assert not wrong.right and "off by 1.00 px" in wrong.text()
    rel = predict.predict_number("q", 105, 100, rtol=0.1, why="w")  # 5 <= 0.1 * 100
    assert rel.right
    missing = predict.predict_number("q", None, 3.0, atol=1, why="the lesson")
    assert missing.verdict == predict.MISSING and "measured 3.00" in missing.text() and "the lesson" in missing.text()


def test_number_never_shows_minus_zero():
    assert "measured 0.00" in predict.predict_number("q", None, -1e-13, atol=1, why="w").text()


def test_choice_ignores_case_and_spaces_and_lists_choices_on_a_typo():
    ok = predict.predict_choice("q", "  Inside ", "inside", ["inside", "leave"], why="w")
    assert ok.right
    assert not predict.predict_choice("q", "leave", "inside", ["inside", "leave"], why="w").right
    with pytest.raises(ValueError, match="'inside', 'leave'"):
        predict.predict_choice("q", "outside", "inside", ["inside", "leave"], why="w")
    with pytest.raises(ValueError, match="not among the choices"):
        predict.predict_choice("q", None, "maybe", ["yes", "no"], why="w")


def test_points_rms_and_shape_errors():
    measured = [(0, 0), (3, 4)]
    assert predict.predict_points("q", [(0, 0), (3, 4.5)], measured, tol=0.5, why="w").right  # rms 0.354
    assert not predict.predict_points("q", [(0, 0), (6, 8)], measured, tol=1.0, why="w").right  # rms 3.54
    with pytest.raises(ValueError, match="give 2 points"):
        predict.predict_points("q", [(0, 0)], measured, tol=1.0, why="w")


def test_bad_input_says_what_to_do():
    with pytest.raises(ValueError, match="must be a number"):
        predict.predict_number("q", "five", 5.0, atol=1, why="w")
    with pytest.raises(ValueError, match="give a tolerance"):
        predict.predict_number("q", 5, 5.0, why="w")


def _prediction_cells(nb):
    return [c for c in nb.cells if c.cell_type == "code" and "predict_" in c.source and "= None" in c.source]


@pytest.mark.parametrize("name", COURSE)
def test_each_notebook_asks_three_predictions_before_checking_them(name):
    nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
    asked = {}
    for i, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        for node in ast.walk(ast.parse(cell.source)):
            if (isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant) and node.value.value is None
                    and node.targets[0].id.startswith("predict_")):
                asked[node.targets[0].id] = i
    assert len(asked) >= 3, f"{name}: only {sorted(asked)}"
    for var, i in asked.items():
        later = [k for k, c in enumerate(nb.cells) if k > i and c.cell_type == "code" and var in c.source
                 and "predict_" in c.source and "(" in c.source]
        assert later, f"{name}: {var} is asked in cell {i} but never checked after it"
        shown = "\n".join(o.get("text", "") + o.get("data", {}).get("text/plain", "")
                          for o in nb.cells[later[0]].get("outputs", []))
        assert "[predict]" in shown and "why:" in shown, f"{name}: the check of {var} shows no explanation"


@pytest.mark.parametrize("name", COURSE)
def test_prediction_cells_are_not_graded_and_reach_students_unchanged(name):
    nb = nbformat.read(str(SOLUTIONS / name), as_version=4)
    cells = _prediction_cells(nb)
    assert cells
    for cell in cells:
        assert release.EXERCISE_TAG not in cell.metadata.get("tags", []), "a prediction cell tagged 'exercise'"
        assert release.BEGIN not in cell.source
    graded = release.solution_functions(SOLUTIONS / name)  # what the grader loads from the notebook
    assert not any(k.startswith("predict") for k in graded), sorted(graded)
    student = release.student_notebook(nb, name)
    assert [c.source for c in _prediction_cells(student)] == [c.source for c in cells]
