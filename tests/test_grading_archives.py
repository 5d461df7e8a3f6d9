"""Hand-in zips and the gradebook, as a course really produces them (issues 22 and 23).

A class folder mixes every layout: a student's folder holding the zip ``dtscal handin`` wrote, such zips
directly in the class folder (the zip names the student), an unpacked folder, a notebook per student, one zip
with 32 files, a zip bomb, a stray file. Every student gets exactly the grades of their unpacked notebooks
(the same class graded unpacked by Python's own zipfile, outside the code under test), every student has a row,
the CSV, the JSON, the class report and the Gradescope bundle agree, and spreadsheet formulas stay text.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from handins import bomb_zip, make_autograder, run_autograder, student_handin

from dtscal_lib.cli import main as dtscal
from dtscal_lib.grading import grade as grade_module
from dtscal_lib.grading.errors import GRADER_ERROR, GraderError
from dtscal_lib.grading.report import csv_cell
from nbtools import ROOT, checks_of

CORRECT = ROOT / "tests" / "grading_corpus_correct"
GiB = 2 ** 30

#: a project_points right on some poses only: a score with a fraction (5.7 of 10 on the kit's cases)
PARTIAL = '''import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, float)
    xc = X @ np.asarray(R, float).T + np.asarray(t, float).reshape(3)
    uv = (xc @ np.asarray(K, float).T)[:, :2] / xc[:, 2:]
    if X[0, 0] > 0:  # a slip on some poses only: partial credit
        uv = uv + 1.0
    return uv
'''


def _zip(path: Path, files: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


def _rows(path: Path) -> dict[str, dict]:
    with open(path, newline="") as fh:
        return {r["student"]: r for r in csv.DictReader(fh)}


def _grade(folder: Path, out: Path, *extra) -> tuple[int, dict, dict]:
    code = dtscal(["grade", str(folder), "--csv", str(out / "grades.csv"), "--json", str(out / "results.json"),
                   "--report", str(out / "report"), "-q", *extra])
    return code, _rows(out / "grades.csv"), json.loads((out / "results.json").read_text())


@pytest.fixture(scope="module")
def klass(tmp_path_factory):
    base = tmp_path_factory.mktemp("archives")
    ada = student_handin(base, "Ada Lovelace", solved=("01_pinhole_projection",))
    carl = student_handin(base, "Carl Gauss", solved=("02_homography",))
    loop, einsum = (CORRECT / "01_pinhole_projection__loop.py").read_bytes(), \
        (CORRECT / "01_pinhole_projection__einsum.py").read_bytes()
    eve_files = {"alice.py": loop, "bob.py": einsum, **{f"notes/{k:02d}.txt": b"scratch" for k in range(30)}}

    zipped = base / "zipped"  # the class as handed in: every layout at once
    (zipped / "ada").mkdir(parents=True)
    shutil.copy(ada, zipped / "ada" / ada.name)  # the zip `dtscal handin` wrote, in the student's folder
    shutil.copy(carl, zipped / carl.name)  # the zip directly in the class folder: the zip names the student
    (zipped / "dora").mkdir()  # an unpacked folder
    (zipped / "dora" / "01_pinhole_projection.py").write_text(PARTIAL)
    _zip(zipped / "eve.zip", eve_files)  # 32 files, two of them solutions of 01: one student
    _zip(zipped / "@SUM(1+1).zip", {"=2+5.py": loop})  # formulas in a student's name and in an entry's name
    (zipped / "=2+5.py").write_bytes(loop)  # a notebook per student, named like a formula
    bomb_zip(zipped / "gus.zip", "01_pinhole_projection.ipynb", 2 * GiB)  # 2 MB holding a 2 GiB notebook
    (zipped / "README.txt").write_text("hand-ins of week 3")  # no student's

    unpacked = base / "unpacked"  # the same class, every zip unpacked by Python's zipfile (not the grader)
    unpacked.mkdir()
    for student, z in (("ada", ada), ("Carl_Gauss", carl), ("eve", zipped / "eve.zip"),
                       ("@SUM(1+1)", zipped / "@SUM(1+1).zip")):
        with zipfile.ZipFile(z) as zf:
            zf.extractall(unpacked / student)
    shutil.copytree(zipped / "dora", unpacked / "dora")
    shutil.copy(zipped / "=2+5.py", unpacked / "=2+5.py")
    (unpacked / "gus").mkdir()  # nothing gradable in the bomb

    (base / "out-z").mkdir()
    (base / "out-u").mkdir()
    zcode, zrows, zjson = _grade(zipped, base / "out-z")
    ucode, urows, ujson = _grade(unpacked, base / "out-u")
    return {"base": base, "ada": ada, "carl": carl, "eve": zipped / "eve.zip", "zrows": zrows, "zjson": zjson,
            "urows": urows, "ujson": ujson, "codes": (zcode, ucode), "report": base / "out-z" / "report"}


def test_every_student_has_a_row_and_no_one_is_dropped(klass):
    students = {"ada", "Carl_Gauss", "dora", "eve", "@SUM(1+1)", "=2+5", "gus"}
    assert klass["codes"] == (0, 0)
    assert {csv_cell(s) for s in students} == set(klass["zrows"])  # the CSV escapes, see below
    assert set(klass["zjson"]["students"]) == students
    assert "README.txt" in " ".join(klass["zjson"]["not_graded"])  # a stray file is named, not dropped
    # notebooks 01-05 for everyone: 1 + 2 + 3 + 3 + 3 functions, 10 points each (05: board_ground_points,
    # pixel_to_ground, camera_height_pitch)
    assert {r["max"] for r in klass["zrows"].values()} == {"120"}


def test_each_student_gets_exactly_their_unpacked_notebooks_grades(klass):
    zrows, urows = klass["zrows"], klass["urows"]
    assert set(zrows) == set(urows)
    funcs = [k for k in next(iter(zrows.values())) if k not in ("student", "notes", "max")]
    assert "project_points" in funcs and "total" in funcs
    for s in zrows:
        assert {f: zrows[s][f] for f in funcs} == {f: urows[s][f] for f in funcs}, s
    # and those grades are the ones the notebooks deserve
    assert zrows["ada"]["project_points"] == "10" and zrows["ada"]["total"] == "10"
    assert zrows["Carl_Gauss"]["total"] == "20" and zrows["Carl_Gauss"]["estimate_homography"] == "10"
    assert 0 < float(zrows["dora"]["total"]) < 10 and float(zrows["dora"]["total"]) % 1  # a fraction
    assert zrows["gus"]["total"] == "0"


def test_a_handin_zip_is_graded_not_called_not_a_notebook(klass):
    for s in ("ada", "Carl_Gauss"):
        notes = klass["zrows"][s]["notes"]
        assert "not a notebook" not in notes and ".zip: not" not in notes
        assert "notebook 06" not in notes and "notebook 03b" not in notes  # ungraded notebooks: once for the class


def test_one_zip_with_32_files_is_one_student(klass):
    rows, js = klass["zrows"], klass["zjson"]["students"]
    assert not {"alice", "bob"} & set(rows)
    assert rows["eve"]["project_points"] == "10"
    assert "eve.zip/bob.py: not graded: eve.zip/alice.py is already graded as 01_pinhole_projection" \
        in rows["eve"]["notes"]
    assert "and 25 more: not a notebook (.ipynb) or .py file; not graded" in rows["eve"]["notes"]
    assert sum(t["name"].startswith("01_pinhole_projection / ") for t in js["eve"]["tests"]) == checks_of(
        "01_pinhole_projection")  # graded once


def test_the_zip_bomb_is_refused_with_a_row_and_a_reason(klass):
    notes = klass["zrows"]["gus"]["notes"]
    assert "gus.zip/01_pinhole_projection.ipynb: 2048.0 MB unpacked, more than the 32 MB" in notes


def test_csv_cells_cannot_become_formulas(klass):
    rows = klass["zrows"]
    assert "'=2+5" in rows and "'@SUM(1+1)" in rows
    assert rows["'=2+5"]["notes"].startswith("'=2+5.py: graded as 01_pinhole_projection")
    assert rows["'@SUM(1+1)"]["notes"].startswith("'@SUM(1+1).zip/=2+5.py: graded as")
    assert rows["'=2+5"]["project_points"] == "10"  # escaping never touches the numbers
    for row in rows.values():
        for value in row.values():
            assert not value.startswith(("=", "+", "-", "@", "\t", "\r")), value
    # OWASP's list, each prefix; numbers and plain text unchanged
    for value in ("=1+1", "+1", "-1", "@SUM(A1)", "\tx", "\rx"):
        assert csv_cell(value) == "'" + value
    assert csv_cell("ada") == "ada" and csv_cell("5.7") == "5.7"


def test_csv_json_and_report_agree(klass):
    rows, js = klass["zrows"], klass["zjson"]["students"]
    page = (klass["report"] / "index.html").read_text()
    assert f"{len(js)} student(s)" in page
    for s, res in js.items():
        row = rows[csv_cell(s)]
        per_function: dict[str, float] = {}
        for t in res["tests"]:
            func = t["name"].split(" / ", 1)[1].split(":", 1)[0]
            per_function[func] = per_function.get(func, 0.0) + t["score"]
        for func, points in per_function.items():
            assert float(row[func]) == pytest.approx(points, abs=0.011), (s, func)  # partial points kept
        assert float(row["total"]) == pytest.approx(res["score"], abs=0.011)
    assert "2048.0 MB unpacked" in page and "README.txt" in page


def test_dtscal_grade_on_one_zip_and_the_gradescope_bundle_agree_with_the_class(klass, tmp_path):
    root = make_autograder(tmp_path)
    for student, z in (("ada", klass["ada"]), ("Carl_Gauss", klass["carl"]), ("eve", klass["eve"])):
        res = run_autograder(root, {z.name: z.read_bytes()})  # the zip as the student uploaded it
        assert f"{z.name}: not" not in res["output"] and "could not grade" not in res["output"]
        assert res["score"] == pytest.approx(float(klass["zrows"][student]["total"]))
        mine = {(t["name"].split(" / ")[-1], t["score"]) for t in res["tests"]}
        theirs = {(t["name"].split(" / ")[-1], t["score"]) for t in klass["zjson"]["students"][student]["tests"]}
        assert mine <= theirs and mine  # the same checks, the same points (eve's bundle run grades 01 only)
        out = tmp_path / f"{student}.json"
        assert dtscal(["grade", str(z), "--json", str(out), "-q"]) == 0  # the instructor, on one zip
        assert json.loads(out.read_text())["score"] == res["score"]
    assert not list((root / "submission").glob("*.ipynb"))  # read from the zip, never unpacked there


# --------------------------------------------------------------------------- caps, without the grader
READ = """
import sys, tempfile
from pathlib import Path
from dtscal_lib.grading.archive import read_zip
scratch = Path(tempfile.mkdtemp())
got = read_zip(sys.argv[1], scratch)
written = sum(p.stat().st_size for p in scratch.rglob("*") if p.is_file())
# VmHWM: this process image's peak (ru_maxrss would carry the forking pytest worker's peak across exec)
hwm = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:"))
print(len(got.members), written, hwm, got.notes)
"""


@pytest.mark.parametrize("declared", [None, 30 * 2 ** 20], ids=["honest", "lying"])
def test_a_zip_bomb_is_refused_without_writing_or_holding_it(tmp_path, declared):
    """2 MB holding 2 GiB (as the issue measured: 4.3 GB of memory, 2 GB written); and a zip whose directory
    lies (declares 30 MiB, under the member cap, for 64 MiB of zeros): refused by the compression ratio."""
    z = bomb_zip(tmp_path / "bomb.zip", "01_pinhole_projection.ipynb", 2 * GiB if declared is None else 2 ** 26,
                 declared)
    assert z.stat().st_size < 3 * 2 ** 20
    run = subprocess.run([sys.executable, "-c", READ, str(z)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    members, written, maxrss_kb, notes = run.stdout.split(" ", 3)
    assert members == "0" and written == "0", notes
    assert int(maxrss_kb) < 400 * 1024  # the interpreter with numpy and OpenCV: ~150 MB; a 2 GiB read: 2 GB
    assert ("2048.0 MB unpacked" if declared is None else "100x its compressed size") in notes


def test_zip_entries_cannot_leave_the_scratch_folder(tmp_path):
    from dtscal_lib.grading.archive import read_zip

    z = _zip(tmp_path / "evil.zip", {"../../escape.py": b"x = 1\n", "/abs/01_pinhole_projection.py": b"y = 2\n",
                                     "sub/../../02_homography.py": b"z = 3\n"})
    into = tmp_path / "scratch"
    into.mkdir()
    got = read_zip(z, into)
    assert sorted(m.name for m in got.members) == ["abs/01_pinhole_projection.py", "escape.py",
                                                   "sub/02_homography.py"]
    assert all(m.path.resolve().is_relative_to(into.resolve()) for m in got.members)
    assert not (tmp_path / "escape.py").exists()


def test_a_broken_zip_gets_a_row_and_says_why(tmp_path):
    klass = tmp_path / "class"
    klass.mkdir()
    (klass / "hal.zip").write_bytes(b"PK\x03\x04 not really a zip")
    shutil.copy(CORRECT / "01_pinhole_projection__loop.py", klass / "ida.py")
    out = tmp_path / "g.csv"
    assert dtscal(["grade", str(klass), "--csv", str(out), "-q"]) == 0
    rows = _rows(out)
    assert set(rows) == {"hal", "ida"} and rows["ida"]["total"] == "10" and rows["hal"]["total"] == "0"
    assert "hal.zip: not a readable zip" in rows["hal"]["notes"]


def test_two_notebooks_of_one_assignment_are_graded_once(tmp_path):
    klass = tmp_path / "class"
    (klass / "jo").mkdir(parents=True)
    shutil.copy(CORRECT / "01_pinhole_projection__loop.py", klass / "jo" / "01_pinhole_projection.py")
    (klass / "jo" / "01_pinhole_projection_v2.py").write_text(PARTIAL)
    out = tmp_path / "g.csv"
    assert dtscal(["grade", str(klass), "--csv", str(out), "-q"]) == 0
    row = _rows(out)["jo"]
    assert row["total"] == "10" and row["max"] == "10"
    assert "01_pinhole_projection_v2.py: not graded: jo/01_pinhole_projection.py is already graded" in row["notes"]


# --------------------------------------------------------------------------- a grader failure is not the student's
def _flaky(fail_times: int, calls: list):
    real = grade_module.run_calls

    def run_calls(*a, **k):
        calls.append(1)
        if len(calls) <= fail_times:
            raise GraderError("the grading process failed to start: out of memory (simulated)")
        return real(*a, **k)

    return run_calls


def test_a_grader_failure_is_retried(tmp_path, monkeypatch, capsys):
    calls: list = []
    monkeypatch.setattr(grade_module, "GRADER_RETRY_PAUSE_S", (0.0, 0.0))
    monkeypatch.setattr(grade_module, "run_calls", _flaky(2, calls))
    out = tmp_path / "r.json"
    assert dtscal(["grade", str(CORRECT / "01_pinhole_projection__loop.py"), "--json", str(out), "-q"]) == 0
    res = json.loads(out.read_text())
    assert res["score"] == 10 and len(calls) == 3 and GRADER_ERROR not in res["output"]


def test_a_persistent_grader_failure_is_reported_as_such_never_as_a_zero(tmp_path, monkeypatch, capsys):
    calls: list = []
    monkeypatch.setattr(grade_module, "GRADER_RETRY_PAUSE_S", (0.0, 0.0))
    monkeypatch.setattr(grade_module, "run_calls", _flaky(10 ** 6, calls))
    klass = tmp_path / "class"
    klass.mkdir()
    shutil.copy(CORRECT / "01_pinhole_projection__loop.py", klass / "kim.py")
    (klass / "lea.py").write_text("def project_points(K, R, t, X):\n    raise NotImplementedError\n")
    out = tmp_path / "out"
    code = dtscal(["grade", str(klass), "--assignment", "01", "--csv", str(out / "g.csv"), "--json",
                   str(out / "r.json"), "--report", str(out / "report"), "-q"])
    assert code == 3  # the command says something is left to rerun
    assert "not graded: grader error, rerun: 1 student(s) (kim)" in capsys.readouterr().err
    assert len(calls) == grade_module.GRADER_ATTEMPTS
    rows = _rows(out / "g.csv")
    assert rows["kim"]["project_points"] == "grader error" and rows["kim"]["total"] == "grader error"
    assert rows["lea"]["project_points"] == "0" and rows["lea"]["total"] == "0"  # a stub needs no sandbox
    assert GRADER_ERROR in rows["kim"]["notes"] and "simulated" in rows["kim"]["notes"]
    kim = json.loads((out / "r.json").read_text())["students"]["kim"]
    # Gradescope's format: no score for what the grader could not run, and then none for the run
    assert kim["output"].startswith(GRADER_ERROR) and kim["extra_data"] == {"status": "grader error",
                                                                            "autograder_failed": True}
    assert "score" not in kim and all("score" not in t for t in kim["tests"])
    assert all(t["output"].startswith(GRADER_ERROR) for t in kim["tests"])
    lea = json.loads((out / "r.json").read_text())["students"]["lea"]
    assert lea["score"] == 0 and all(t["score"] == 0 for t in lea["tests"])
    page = (out / "report" / "index.html").read_text()
    assert 'id="grader-errors"' in page and "kim" in page.split('id="grader-errors"')[1]
    assert "mean total 0.0 / 10 points over the 1 fully graded" in page  # kim's total is not known yet



def test_one_student_takes_loose_notebooks_and_zips_alike(tmp_path):
    """Gradescope's submission folder (``--one-student``): a notebook uploaded beside the hand-in zip that holds
    the same notebook is graded once (the loose one), the zip's others are graded, nothing becomes a student."""
    from dtscal_lib.grading.classroom import roster

    sub = tmp_path / "submission"
    sub.mkdir()
    loop = (CORRECT / "01_pinhole_projection__loop.py").read_bytes()
    (sub / "01_pinhole_projection.py").write_bytes(loop)
    _zip(sub / "Ada.zip", {"01_pinhole_projection.py": loop, "02_homography.py": b"def apply_homography(H, p):\n"
                                                                                  b"    return p\n"})
    r = roster(sub, one_student="submission")
    try:
        assert r.students == ["submission"]
        assert [(i.shown, i.assignment) for i in r.items] == [
            ("01_pinhole_projection.py", "01_pinhole_projection"), ("Ada.zip/02_homography.py", "02_homography")]
        assert any("Ada.zip/01_pinhole_projection.py: not graded: 01_pinhole_projection.py is already graded" in n
                   for n in r.notes["submission"])
        scratch = r.items[1].path
        assert scratch.is_file() and not scratch.is_relative_to(sub)  # never unpacked into the submission
    finally:
        r.cleanup()
    assert not scratch.exists()  # and removed afterwards


# --------------------------------------------------------------------------- hidden entries, sizes, names
def _correct(assignment: str) -> bytes:
    return sorted(CORRECT.glob(f"{assignment}__*.py"))[0].read_bytes()


def test_dot_folders_and_macos_droppings_are_never_graded(tmp_path):
    """A stale ``.ipynb_checkpoints`` copy, macOS's ``__MACOSX`` AppleDouble files and anything in a dot-folder,
    in a zip or in a student's folder, are not graded (nor taken for a second copy of a graded notebook)."""
    from dtscal_lib.grading.classroom import roster

    stale = {".ipynb_checkpoints/01_pinhole_projection-checkpoint.py": _correct("01_pinhole_projection"),
             "__MACOSX/._02_homography.py": b"\x00\x05\x16\x07 AppleDouble",
             "work/.hidden/01_pinhole_projection.py": _correct("01_pinhole_projection")}
    (tmp_path / "class").mkdir()
    _zip(tmp_path / "class" / "ada.zip", {"02_homography.py": _correct("02_homography"), **stale})
    for rel, data in {"02_homography.py": _correct("02_homography"), **stale}.items():
        (tmp_path / "class" / "bob" / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "class" / "bob" / rel).write_bytes(data)
    r = roster(tmp_path / "class")
    try:
        assert sorted((i.student, i.assignment, i.shown) for i in r.items) == [
            ("ada", "02_homography", "ada.zip/02_homography.py"), ("bob", "02_homography", "bob/02_homography.py")]
        assert r.assignments == ["02_homography"]  # no copy of 01 anywhere made it a column
        for s in ("ada", "bob"):
            notes = r.notes.get(s, [])
            assert not any("checkpoint" in n or "MACOSX" in n or "hidden" in n for n in notes), notes
    finally:
        r.cleanup()


def test_an_entry_is_capped_by_its_size_whatever_its_header_says(tmp_path):
    """A stored (uncompressed: no ratio to betray it) 40 MiB notebook, over the 32 MiB member cap: refused by its
    header before a byte is read; the same entry whose header claims 1 kB yields no more than that (Python's
    zipfile stops at the declared size, then the CRC fails): nothing of it is written, the student is told."""
    from dtscal_lib.grading.archive import MAX_MEMBER_BYTES, read_zip

    big = 40 * 2 ** 20
    assert big > MAX_MEMBER_BYTES
    honest = tmp_path / "honest.zip"
    with zipfile.ZipFile(honest, "w", zipfile.ZIP_STORED) as z:
        z.writestr("01_pinhole_projection.ipynb", bytes(big))
    data = honest.read_bytes()
    lying = tmp_path / "lying.zip"  # the central directory's uncompressed size (offset 24) says 1 kB
    cd = data.rindex(b"PK\x01\x02")
    lying.write_bytes(data[:cd + 24] + (1024).to_bytes(4, "little") + data[cd + 28:])
    for z, said in ((honest, "40.0 MB unpacked, more than the 32 MB"), (lying, "cannot be unpacked")):
        into = tmp_path / f"scratch-{z.stem}"
        into.mkdir()
        got = read_zip(z, into)
        assert not got.members and any(said in n for n in got.notes), got.notes
        assert not any(into.rglob("*.ipynb"))


def test_a_folder_and_a_file_with_one_name_are_two_students(tmp_path):
    """``alice/`` and ``alice.py`` in one class folder: two hand-ins, two rows, and the rule said in the row."""
    from dtscal_lib.grading.classroom import roster

    (tmp_path / "class" / "alice").mkdir(parents=True)
    (tmp_path / "class" / "alice" / "02_homography.py").write_bytes(_correct("02_homography"))
    (tmp_path / "class" / "alice.py").write_bytes(_correct("01_pinhole_projection"))
    (tmp_path / "class" / "bob.py").write_bytes(_correct("01_pinhole_projection"))
    r = roster(tmp_path / "class")
    assert sorted(r.students) == ["alice", "alice.py", "bob"]
    assert sorted((i.student, i.assignment) for i in r.items) == [
        ("alice", "02_homography"), ("alice.py", "01_pinhole_projection"), ("bob", "01_pinhole_projection")]
    assert any("alice/, alice.py share the name 'alice'" in n and "two hand-ins" in n for n in r.notes["alice.py"])
    assert not any("already graded" in n for s in r.students for n in r.notes.get(s, []))
