"""A class folder as instructors hand it over: unusual names, an empty folder, a missing
notebook, an ungraded notebook, mixed assignments, a syntax error. Every student gets one
row with the same maximum, every file is accounted for in the CSV and JSON (not only on
stderr), and the class report page opens in Chromium and shows the table.
"""

from __future__ import annotations

import csv
import json
import shutil

import pytest
from browser import launch_chromium

from dtscal_lib.cli import main as dtscal
from nbtools import ROOT

SOL = ROOT / "solutions"
CORPUS = ROOT / "tests" / "grading_corpus"
# the name of a mistake of the corpus that the diagnosis names (asserted on the page)
BUGGY = CORPUS / "02_homography__apply_H_transposed.py"


def _syntax_error_notebook(path):
    nb = json.loads((SOL / "02_homography.ipynb").read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    code[1]["source"] = "x = 1\ny = 2\ndef broken(:\n    pass\n"
    path.write_text(json.dumps(nb))
    return 2, 3  # code cell 2, line 3


@pytest.fixture(scope="module")
def klass(tmp_path_factory):
    root = tmp_path_factory.mktemp("class")
    (root / "alice").mkdir()
    shutil.copy(SOL / "02_homography.ipynb", root / "alice" / "homework2.ipynb")  # another name
    shutil.copy(SOL / "06_duckiebot_camera.ipynb", root / "alice" / "06_duckiebot_camera.ipynb")
    (root / "bob").mkdir()  # empty
    (root / "carol").mkdir()
    shutil.copy(SOL / "01_pinhole_projection.ipynb", root / "carol" / "01_pinhole_projection.ipynb")
    (root / "carol" / "notes.txt").write_text("hello")
    (root / "dave").mkdir()
    shutil.copy(BUGGY, root / "dave" / "02_homography.py")
    (root / "erin").mkdir()
    cell, line = _syntax_error_notebook(root / "erin" / "02_homography.ipynb")
    out = root.parent / (root.name + "_out")
    code = dtscal(["grade", str(root), "--csv", str(out / "grades.csv"), "--json", str(out / "results.json"),
                   "--report", str(out / "report"), "--jobs", "2", "-q"])
    assert code == 0
    rows = {r["student"]: r for r in csv.DictReader(open(out / "grades.csv"))}
    return {"rows": rows, "json": json.loads((out / "results.json").read_text()), "out": out,
            "where": f"code cell {cell}, line {line}"}


def test_one_row_per_student_same_max(klass):
    rows = klass["rows"]
    assert sorted(rows) == ["alice", "bob", "carol", "dave", "erin"]
    assert {r["max"] for r in rows.values()} == {"30"}  # notebooks 01 (10) + 02 (20), for everyone
    assert set(klass["json"]["students"]) == set(rows)


def test_every_file_accounted_for(klass):
    rows, js = klass["rows"], klass["json"]["students"]
    # a notebook under another name, matched by its functions and graded
    assert rows["alice"]["estimate_homography"] == "10" and rows["alice"]["apply_homography"] == "10"
    assert "homework2.ipynb: graded as 02_homography" in rows["alice"]["notes"]
    assert "notebook 06" not in rows["alice"]["notes"]  # said once for the class, not in each row (issue 32)
    assert "01_pinhole_projection: not handed in" in rows["alice"]["notes"] and rows["alice"]["project_points"] == "0"
    # an empty folder: zeros and the reason
    assert rows["bob"]["total"] == "0" and "no notebook or .py file handed in" in rows["bob"]["notes"]
    assert all(rows["bob"][f] == "0" for f in ("project_points", "apply_homography", "estimate_homography"))
    # a missing assignment is 0 with "not handed in"; a stray file is listed
    assert rows["carol"]["total"] == "10" and "02_homography: not handed in" in rows["carol"]["notes"]
    assert "notes.txt: not a notebook" in rows["carol"]["notes"]
    for s in ("alice", "bob", "carol"):
        assert any("not handed in" in t["output"] for t in js[s]["tests"])
    assert "not graded: notebook 06" in js["alice"]["output"]


def test_syntax_error_in_the_students_cell_and_line(klass):
    assert f"{klass['where']}: invalid syntax" in klass["rows"]["erin"]["notes"]


def test_assignment_never_grades_another_notebook(tmp_path, capsys):
    d = tmp_path / "class" / "frank"
    d.mkdir(parents=True)
    shutil.copy(SOL / "01_pinhole_projection.ipynb", d / "01_pinhole_projection.ipynb")
    shutil.copy(SOL / "06_duckiebot_camera.ipynb", d / "06_duckiebot_camera.ipynb")
    shutil.copy(SOL / "03b_calibration_quality.ipynb", d / "03b_calibration_quality.ipynb")
    shutil.copy(SOL / "01_pinhole_projection.ipynb", d / "mystery.ipynb")
    out = tmp_path / "g.csv"
    assert dtscal(["grade", str(tmp_path / "class"), "--assignment", "02", "--csv", str(out), "-q"]) == 0
    row = next(csv.DictReader(open(out)))
    assert row["total"] == "0" and row["max"] == "20"
    assert "its name says notebook 01_pinhole_projection, not 02_homography" in row["notes"]
    assert "mystery.ipynb: not graded as 02_homography: it defines the functions of 01" in row["notes"]
    assert "notebook 06" not in row["notes"] and "notebook 03b" not in row["notes"]  # once for the class:
    said = capsys.readouterr().err
    assert said.count("is not graded") == 2 and "not graded, for the whole class (1 student(s) handed it in): " \
        "notebook 03b" in said  # no exercise, not an error
    assert "02_homography: not handed in" in row["notes"]


@pytest.mark.parametrize("args", [["--wall", "nan"], ["--wall", "-1"], ["--wall", "1e300"], ["--cpu", "-1"],
                                  ["--mem", "1"], ["--jobs", "0"]])
def test_limits_are_validated(tmp_path, capsys, args):
    assert dtscal(["grade", str(SOL / "02_homography.ipynb"), *args, "-q"]) == 2
    err = capsys.readouterr().err
    assert args[0] in err and "between" in err and "Traceback" not in err


def test_class_report_in_chromium(klass):
    from playwright.sync_api import sync_playwright

    page_path = klass["out"] / "report" / "index.html"
    assert page_path.is_file()
    with sync_playwright() as p:
        browser = launch_chromium(p)
        try:
            page = browser.new_page()
            page.goto(page_path.as_uri())
            assert page.title() == "dtscal grade: class report"
            dist = page.locator("#distribution tbody tr")
            assert dist.count() == 3  # project_points, apply_homography, estimate_homography
            assert "5 student(s)" in page.locator("#summary").inner_text()
            first = page.locator("#mistakes tbody tr").first.locator("td")
            assert first.nth(1).inner_text() == "apply_homography"
            assert first.nth(2).inner_text() == "1" and first.nth(3).inner_text() == "dave"
            assert first.nth(4).inner_text().strip()  # the equation to revisit
            assert page.locator("#notes tbody tr").count() >= 5
        finally:
            browser.close()


def test_notebook_03b_names_no_assignment_and_is_listed_as_not_graded(tmp_path, capsys):
    """Issue 24 split notebook 03: its later half, 03b, has no graded function, so it is not graded (like 06), and
    its name never makes the grader take it for notebook 03."""
    from dtscal_lib.grading.material import ASSIGNMENTS, assignment_of

    assert assignment_of("03b_calibration_quality.ipynb") is None
    assert assignment_of("homework-03b_calibration_quality.ipynb") is None
    assert assignment_of("03_intrinsic_calibration.ipynb") == "03_intrinsic_calibration"
    assert "03b_calibration_quality" not in ASSIGNMENTS
    out = tmp_path / "g.csv"
    assert dtscal(["grade", str(SOL / "03b_calibration_quality.ipynb"), "--csv", str(out), "-q"]) == 0
    notes = next(csv.DictReader(open(out)))["notes"] + capsys.readouterr().err  # the row, and the class's note
    assert "not graded, for the whole class (1 student(s) handed it in): notebook 03b" in notes
    assert "pass --assignment" not in notes
    assert dtscal(["grade", str(SOL / "03b_calibration_quality.ipynb"), "--assignment", "03b", "--csv",
                   str(out), "-q"]) == 2
