"""Limits no student can move (issue 28, item 6): a notebook's cell count, the uid slots' folder,
and the grader's memory, which follows one check's answers, not the sum of a submission's."""

from __future__ import annotations

import json

from dtscal_lib.grading.grade import grade_file
from dtscal_lib.grading.loader import MAX_CELLS
from dtscal_lib.grading.material import Material
from dtscal_lib.grading.report import text
from nbtools import ROOT


def _notebook(path, cells: int):
    code = [{"cell_type": "code", "metadata": {}, "execution_count": None, "outputs": [], "source": "x = 1"}]
    path.write_text(json.dumps({"cells": code * cells, "metadata": {}, "nbformat": 4, "nbformat_minor": 5}))
    return path


def test_a_notebook_with_too_many_cells_is_refused_with_the_bound(tmp_path):
    """10,000 cells once took 75 s to grade: past MAX_CELLS the notebook is not read, and the
    student reads why (0, never a grader error)."""
    m = Material.load(ROOT)
    res = grade_file(_notebook(tmp_path / "02_homography.ipynb", MAX_CELLS + 1), m, "02_homography")
    said = text(res)
    assert f"has {MAX_CELLS + 1} cells, more than the {MAX_CELLS}" in said, said
    assert res.score == 0 and not res.grader_error
    res = grade_file(_notebook(tmp_path / "ok" / "02_homography.ipynb", MAX_CELLS) if (tmp_path / "ok").mkdir()
                     is None else None, m, "02_homography")
    assert "cells, more than" not in text(res)
