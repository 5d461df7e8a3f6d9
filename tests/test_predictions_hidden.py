"""Predictions a student cannot read off (issue 29): every answer and explanation lives in the library, keyed by the
question, and nothing a student reads before the check gives it away.

The scan reads what a student has in front of them: the student notebook generated from each solution notebook
(every cell's source, prose included, and its stored outputs), and the outputs a student sees when running the cells
above a check (the solution notebook's stored outputs of the cells before it). It looks for each prediction's
answer: the explanation the check prints (read from the solution notebook's stored output of the check), the
measured value as the check prints it, and the phrases ``dtscal_lib.teaching.selfcheck.answers`` lists as giving the
answer away.
"""

from __future__ import annotations

import re

import nbformat
import pytest

from dtscal_lib.teaching import release
from dtscal_lib.teaching.selfcheck import answers, check_prediction, predict
from nbtools import NOTEBOOKS, SOLUTIONS

COURSE = ["01_pinhole_projection.ipynb", "02_homography.ipynb", "03_intrinsic_calibration.ipynb",
          "03b_calibration_quality.ipynb", "04_distortion_rectification.ipynb", "05_extrinsic_calibration.ipynb"]
CHECK_RE = re.compile(r'check_prediction\(\s*"([0-9a-z]+\.\w+)"')
#: a run of this many words of an explanation found in a notebook counts as the explanation (6 words are a phrase)
WINDOW = 6


def _outputs(cell) -> str:
    out = []
    for o in cell.get("outputs", []):
        out.append(o.get("text", "") if o.get("output_type") == "stream" else o.get("data", {}).get("text/plain", ""))
    return "\n".join(out)


def _words(text: str) -> list[str]:
    return re.findall(r"[a-z0-9][a-z0-9'.^/+-]*", text.lower())


def _windows(text: str) -> set[tuple[str, ...]]:
    w = _words(text)
    return {tuple(w[i:i + WINDOW]) for i in range(len(w) - WINDOW + 1)}


def _checks(nb) -> list[tuple[str, int, str]]:
    """(question key, index of the check cell, what the check printed) for every check of the notebook."""
    found = []
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "code":
            for key in CHECK_RE.findall(cell.source):
                found.append((key, i, _outputs(cell)))
    return found


def _printed(key: str, output: str) -> tuple[str, str]:
    """The measured value (as printed, '' for a choice) and the explanation of ``key`` in a check cell's output."""
    q = answers.question(key)
    block = output.split(f"[predict] {q.text}", 1)
    assert len(block) == 2, f"{key}: the check's output does not show the question {q.text!r}"
    body = block[1].split("[predict]", 1)[0]
    why = re.search(r"^    why: (.*)$", body, re.MULTILINE)
    assert why, f"{key}: the check printed no explanation"
    measured = re.search(r"measured (-?[0-9.]+)", body)
    return ("" if q.is_choice else measured.group(1)), why.group(1)


def _number_in(value: str, text: str) -> bool:
    return re.search(rf"(?<![0-9.]){re.escape(value)}(?![0-9])", text) is not None


SOLUTION_NBS = {name: nbformat.read(str(SOLUTIONS / name), as_version=4) for name in COURSE}


def test_every_question_is_asked_once_in_its_own_notebook():
    used = {}
    for name, nb in SOLUTION_NBS.items():
        for key, _i, _out in _checks(nb):
            assert key not in used, f"{key} is checked twice ({used[key]}, {name})"
            used[key] = name
            assert name.startswith(key.split(".")[0] + "_"), f"{key} is checked in {name}"
            var = answers.question(key).var
            asked = [c for c in nb.cells[:_i] if c.cell_type == "code" and re.search(rf"^{var} = None", c.source, re.M)]
            assert asked, f"{name}: {var} is checked but never asked (`{var} = None`) above the check"
    assert sorted(used) == sorted(answers.QUESTIONS), "questions in the library that no notebook asks, or the reverse"


@pytest.mark.parametrize("name", COURSE)
def test_no_student_notebook_shows_an_answer_before_its_check(name):
    sol = SOLUTION_NBS[name]
    student = release.student_notebook(sol, name)  # what notebooks/ holds (test_release checks they agree)
    shown = "\n".join(c.source + "\n" + _outputs(c) for c in student.cells)
    assert "why=" not in shown, f"{name}: an explanation written in the notebook (why=...)"
    assert not re.search(r"predict_(number|choice|points)\(", shown), f"{name}: a check not keyed by its question"
    shown_windows = _windows(shown)
    leaks = []
    for key, i, output in _checks(sol):
        q = answers.question(key)
        measured, why = _printed(key, output)
        before = "\n".join(_outputs(c) for c in sol.cells[:i])  # what running the cells above prints
        for phrase in q.giveaways:
            if phrase.lower() in shown.lower():
                leaks.append(f"{key}: the notebook says {phrase!r}")
            if phrase.lower() in before.lower():
                leaks.append(f"{key}: a cell above the check prints {phrase!r}")
        common = _windows(why) & shown_windows
        if common:
            leaks.append(f"{key}: the notebook repeats its explanation: {' '.join(sorted(common)[0])!r}")
        if len(measured.replace(".", "")) >= 3:  # "1.61", "117", "10.4": a number that stands for the answer
            if _number_in(measured, shown):
                leaks.append(f"{key}: the notebook holds the answer {measured}")
            if _number_in(measured, before):
                leaks.append(f"{key}: a cell above the check prints the answer {measured}")
    assert not leaks, f"{name}:\n" + "\n".join(leaks)


@pytest.mark.parametrize("name", COURSE)
def test_the_generated_notebooks_are_the_ones_scanned(name):
    have = nbformat.read(str(NOTEBOOKS / name), as_version=4)
    want = release.student_notebook(SOLUTION_NBS[name], name)
    assert [c.source for c in have.cells] == [c.source for c in want.cells]
    assert not any(c.get("outputs") for c in have.cells if c.cell_type == "code")


def _sample(q):
    return q.choices[-1] if q.is_choice else 3.0


@pytest.mark.parametrize("key", sorted(answers.QUESTIONS))
def test_a_prediction_typed_as_text_names_its_variable_and_keeps_the_answer(key):
    q = answers.question(key)
    facts = {"distance": 0.5, "u_min": 300.0, "u_max": 360.0, "half_fov_deg": 46.0, "rms": 2.3, "frame": 304,
             "spread": 0.0, "shift_lo": 3.4, "shift_hi": 5.0, "involved": "B11", "err_px": 24.7, "rms_cf": 4.9,
             "noise_px": 0.2, "err_3": 7.9, "pinhole_deg": 92.0, "K": [[307.7, 0, 329.7], [0, 315.0, 244.5]],
             "dist": [-0.26, 0.045, 0, 0, 0], "new_fx": 210.3, "fx": 307.7, "yaw_deg": 2.0, "x_ahead_m": 0.5}
    typed = check_prediction(key, "my guess: about 12 or so", _sample(q), **facts)  # never raises
    text = typed.text()
    assert typed.verdict == predict.UNREAD and q.var in text and "run this cell again" in text
    assert "why:" not in text and "Traceback" not in text
    right = check_prediction(key, _sample(q), _sample(q), **facts)
    assert right.right and "why:" in right.text() and len(right.why) > 40


@pytest.mark.parametrize("key, wrong, facts, says", [
    ("01.width_ratio", 0.62, {}, "Your 0.62 is 0.28 / 0.45"),
    ("01.yaw60", "leave", {"distance": 0.5, "u_min": 305, "u_max": 364, "half_fov_deg": 46.1}, "turned about its OWN"),
    ("05.yaw_mm", 454.6, {"yaw_deg": 2.0, "x_ahead_m": 0.5}, "Your 455 mm took 2 as radians"),
    ("05.pitch_deg", 0.31, {}, "Your 0.31 deg is the pitch in radians"),
    ("05.height_cm", 0.104, {}, "looks like metres"),
    ("03.rank_parallel", 20, {}, "Your 20 counts 2 equations per view"),
])
def test_a_wrong_prediction_is_explained_with_the_students_own_number(key, wrong, facts, says):
    measured = {"01.width_ratio": 1.61, "01.yaw60": "inside", "05.yaw_mm": 17.4, "05.pitch_deg": 18.0,
                "05.height_cm": 10.4, "03.rank_parallel": 2}[key]
    res = check_prediction(key, wrong, measured, **facts)
    assert not res.right and says in res.why, res.text()
