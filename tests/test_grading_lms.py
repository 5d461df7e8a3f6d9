"""LMS exports graded by student: a Canvas or Moodle "download all submissions" folder gives one row per
student with the LMS's name and id, the latest submission graded, the earlier ones listed, LATE reported.

The file names follow the LMSs' own code (see :mod:`dtscal_lib.grading.lms` for the sources): Canvas's
``content_zipper.rb`` (``lovelaceada[_LATE]_{user id}_{file id}_{file}``, a re-upload of the same name
getting ``-1``), Moodle's ``downloader.php`` (``{Full Name}_{participant id}_assignsubmission_file`` folders,
or ``..._assignsubmission_file_{file}`` files). Any other layout keeps the grader's usual rules.
"""

from __future__ import annotations

import csv
import json
import zipfile
from pathlib import Path

import pytest

from dtscal_lib.cli import main as dtscal
from dtscal_lib.grading.classroom import roster
from nbtools import ROOT

RIGHT = sorted((ROOT / "tests" / "grading_corpus_correct").glob("01_pinhole_projection__*.py"))[0].read_bytes()
WRONG = (ROOT / "tests" / "grading_corpus" / "01_pinhole_projection__K_transposed.py").read_bytes()
NB01 = "01_pinhole_projection.py"


def _zip(path: Path, files: dict[str, bytes]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


def _canvas(root: Path) -> Path:
    """Ada resubmitted (her first zip is wrong, the re-upload right: Canvas named it handin-1.zip); Cara
    handed in late; Charles uploaded a loose file."""
    _zip(root / "lovelaceada_12341_62341_handin.zip", {NB01: WRONG})
    _zip(root / "lovelaceada_12341_62399_handin-1.zip", {NB01: RIGHT})
    _zip(root / "chencara_LATE_12343_62343_handin.zip", {NB01: RIGHT})
    (root / f"babbagecharles_12342_62342_{NB01}").write_bytes(RIGHT)
    return root


@pytest.fixture(scope="module")
def canvas_graded(tmp_path_factory):
    root = _canvas(tmp_path_factory.mktemp("canvas") / "submissions")
    out = root.parent / "out"
    assert dtscal(["grade", str(root), "--csv", str(out / "g.csv"), "--json", str(out / "r.json"), "-q"]) == 0
    with open(out / "g.csv", newline="") as fh:
        rows = {r["student"]: r for r in csv.DictReader(fh)}
    return rows, json.loads((out / "r.json").read_text())["students"]


def test_canvas_one_row_per_student_with_canvas_name_and_id(canvas_graded):
    rows, js = canvas_graded
    assert sorted(rows) == ["babbagecharles (Canvas 12342)", "chencara (Canvas 12343)", "lovelaceada (Canvas 12341)"]
    assert set(js) == set(rows)


def test_canvas_the_latest_submission_is_graded_and_the_earlier_listed(canvas_graded):
    rows, js = canvas_graded
    ada = rows["lovelaceada (Canvas 12341)"]
    assert float(ada["total"]) == float(rows["babbagecharles (Canvas 12342)"]["total"]) == 10  # the right re-upload
    assert ("lovelaceada_12341_62341_handin.zip: an earlier submission, not graded: the latest, "
            "lovelaceada_12341_62399_handin-1.zip, is") in ada["notes"]
    assert "already graded" not in ada["notes"]
    assert js["lovelaceada (Canvas 12341)"]["score"] == 10


def test_canvas_late_is_reported(canvas_graded):
    rows, js = canvas_graded
    cara = rows["chencara (Canvas 12343)"]
    assert float(cara["total"]) == 10  # late is reported, the points are the instructor's call
    assert "chencara_LATE_12343_62343_handin.zip: LATE: Canvas marked this submission late" in cara["notes"]
    assert "LATE" in js["chencara (Canvas 12343)"]["output"]
    assert "LATE" not in rows["lovelaceada (Canvas 12341)"]["notes"]


def test_canvas_lower_cased_late_and_an_earlier_late_submission(tmp_path):
    """Canvas versions that lower-case the whole name (``_late_``) are read the same; a late first try
    superseded by an on-time upload is listed as late and not graded."""
    _zip(tmp_path / "c" / "hopperg_late_77_901_handin.zip", {NB01: WRONG})
    _zip(tmp_path / "c" / "hopperg_77_950_handin-1.zip", {NB01: RIGHT})
    r = roster(tmp_path / "c")
    try:
        assert r.students == ["hopperg (Canvas 77)"]
        assert [i.shown for i in r.items] == [f"hopperg_77_950_handin-1.zip/{NB01}"]
        assert r.notes["hopperg (Canvas 77)"] == [
            "hopperg_late_77_901_handin.zip: an earlier submission (Canvas marked it LATE), not graded: the latest, "
            "hopperg_77_950_handin-1.zip, is"]
    finally:
        r.cleanup()


def test_moodle_folders_and_files_by_participant(tmp_path):
    """Moodle 4.2+ folders (no trailing ``_``), Moodle 3.1-4.1 folders (trailing ``_``), and the flat layout."""
    folders = tmp_path / "folders"
    _zip(folders / "Ada Lovelace_501_assignsubmission_file" / "handin.zip", {NB01: RIGHT})
    (folders / "Grace Hopper_502_assignsubmission_file_").mkdir(parents=True)
    (folders / "Grace Hopper_502_assignsubmission_file_" / NB01).write_bytes(RIGHT)
    flat = tmp_path / "flat"
    _zip(flat / "Ada Lovelace_501_assignsubmission_file_handin.zip", {NB01: RIGHT})
    (flat / f"Grace Hopper_502_assignsubmission_file_{NB01}").write_bytes(RIGHT)
    for root in (folders, flat):
        r = roster(root)
        try:
            assert r.students == ["Ada Lovelace (Moodle 501)", "Grace Hopper (Moodle 502)"], root.name
            assert sorted(i.student for i in r.items) == r.students
            assert not any(r.notes.values()), r.notes
        finally:
            r.cleanup()


def test_any_other_layout_keeps_todays_rules(tmp_path):
    """One hand-in that follows no LMS convention: the folder is not an export; every file is its own student."""
    _canvas(tmp_path / "mixed")
    _zip(tmp_path / "mixed" / "bob.zip", {NB01: RIGHT})
    r = roster(tmp_path / "mixed")
    try:
        assert "bob" in r.students and "lovelaceada_12341_62341_handin" in r.students
        assert not any("Canvas" in s for s in r.students)
    finally:
        r.cleanup()


def test_the_export_zip_itself_is_refused_with_the_command_to_unpack_it(tmp_path, capsys):
    """Canvas's download is one zip of the whole class: never graded as one student named after the zip."""
    folder = _canvas(tmp_path / "c")
    export = tmp_path / "course-assignment_submissions.zip"
    with zipfile.ZipFile(export, "w") as z:
        for p in sorted(folder.iterdir()):
            z.write(p, p.name)
    assert dtscal(["grade", str(export), "--csv", str(tmp_path / "g.csv"), "-q"]) != 0
    err = capsys.readouterr().err
    assert "is a Canvas export" in err and f"unzip {export} -d submissions" in err
    assert not (tmp_path / "g.csv").exists()
    moodle = tmp_path / "moodle.zip"
    _zip(moodle, {f"Ada Lovelace_501_assignsubmission_file/{NB01}": RIGHT,
                  f"Grace Hopper_502_assignsubmission_file/{NB01}": RIGHT})
    assert dtscal(["grade", str(moodle), "-q"]) != 0
    assert "is a Moodle export" in capsys.readouterr().err
