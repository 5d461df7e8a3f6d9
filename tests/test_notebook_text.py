"""What the notebooks' prose says about their own output is true, on the solution path and on the stand-in path.

The solution path is read from the stored outputs of solutions/ (what nbval keeps in sync); the
stand-in path is what a student sees before writing any function: the generated notebook,
executed as handed out. Each claim below quotes the prose it checks.
"""

from __future__ import annotations

import re

import nbformat
import pytest

from nbtools import SOLUTIONS, execute_student_once

NB02, NB03 = "02_homography.ipynb", "03_intrinsic_calibration.ipynb"


def _text(nb) -> str:
    out = []
    for cell in nb.cells:
        for o in cell.get("outputs", []):
            if o.get("output_type") == "stream":
                out.append(o["text"])
            elif "text/plain" in o.get("data", {}):
                out.append(o["data"]["text/plain"])
    return "\n".join(out)


def _prose(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")


def _table_err(text: str, label: str) -> float:
    """The 'max |err|' column of a row of course.intrinsics_table (the last printed one)."""
    rows = [line for line in text.splitlines() if line.startswith(label)]
    assert rows, f"no table row {label!r} in the output"
    return float(rows[-1].split()[-1].rstrip("px"))


def _claims_02(nb) -> None:
    prose, text = _prose(nb), _text(nb)
    assert "agree to a fraction of\na percent" in prose
    rel = float(re.search(r"and OpenCV's: ([0-9.e+-]+) of the largest entry", text).group(1))
    assert rel < 0.01
    assert "A normalized fit stays at round-off level throughout." in prose
    assert re.search(r"normalized DLT.*: below 1e-08 px at every offset", text)
    assert "DLT without normalization: above 1e-06 px" in text
    assert "np.float64(" not in text


def _claims_03(nb) -> None:
    prose, text = _prose(nb), _text(nb)
    assert "off by several pixels (the table's last column)" in prose
    assert _table_err(text, "closed form, detected corners") > 3.0
    assert "lands within a\nfraction of a pixel of the truth" in prose
    assert _table_err(text, "full calibration (with distortion)") < 0.5
    assert "On undistorted corners the closed form lands within about a pixel of the truth" in prose
    assert _table_err(text, "closed form, undistorted (truth)") < 1.0
    assert _table_err(text, "closed form, undistorted (full calib.)") < 1.0  # the label is not cut
    assert ("per-view RMS error reaches several pixels, while the full\ncalibration stays far below a pixel "
            "on every view") in prose
    worst_cf = float(re.search(r"closed form: worst view ([0-9.]+) px RMS", text).group(1))
    worst_full = float(re.search(r"full calibration: worst view ([0-9.]+) px RMS", text).group(1))
    assert worst_cf > 3.0 and worst_full < 0.5
    assert "np.float64(" not in text


CLAIMS = {NB02: _claims_02, NB03: _claims_03}


@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_prose_matches_stored_solution_outputs(name):
    CLAIMS[name](nbformat.read(str(SOLUTIONS / name), as_version=4))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_prose_matches_what_a_student_sees_first(name, notebook_runs):
    nb, _ = execute_student_once(name.removesuffix(".ipynb"), notebook_runs)  # the run test_notebooks checks
    text = _text(nb)
    assert "!! -> using" in text  # the stand-in path really ran (a banner said so)
    CLAIMS[name](nb)
