"""`dtscal release --nbgrader COURSE` hands the course to real nbgrader (PyPI, the [test] extra).

nbgrader's own commands run on the export: `generate_assignment` makes the students' copy (solutions
and hidden tests stripped by nbgrader itself), then `autograde` grades students' copies filled with
right, wrong and partly right code from the grading corpus. Each function's nbgrader score (read from
nbgrader's gradebook) equals `dtscal grade`'s on the same notebooks (its CSV, one column per function),
and at least one score is partial, so the test cells' numbers carry over rather than all-or-nothing.
"""

from __future__ import annotations

import ast
import csv
import json
import re
import os
import runpy
import subprocess
import sys
from pathlib import Path

import pytest
from ci import missing

from dtscal_lib.cli import main as dtscal
from nbtools import ROOT

pytestmark = pytest.mark.slow

CORPUS = ROOT / "tests" / "grading_corpus"
CORRECT = ROOT / "tests" / "grading_corpus_correct"
#: student -> (assignment, corpus files whose functions replace the solution's)
STUDENTS = {
    "alice": ("01_pinhole_projection", [CORRECT / "01_pinhole_projection__loop.py"]),
    "bob": ("01_pinhole_projection", [CORPUS / "01_pinhole_projection__K_transposed.py"]),
    "carol": ("01_pinhole_projection", [CORPUS / "01_pinhole_projection__modifies_input.py"]),
    # a right estimate_homography that calls apply_homography, then a wrong apply_homography (the later wins)
    "erin": ("02_homography", [CORRECT / "02_homography__hartley_svd_calls_apply.py",
                               CORPUS / "02_homography__apply_H_transposed.py"]),
    "frank": ("02_homography", [CORPUS / "02_homography__estimate_not_scaled.py"]),
}
ASSIGNMENTS = sorted({a for a, _ in STUDENTS.values()})
HIDDEN = ("### BEGIN HIDDEN TESTS", "### END HIDDEN TESTS")


def _nbgrader(course: Path, *args) -> subprocess.CompletedProcess:
    out = subprocess.run([sys.executable, "-m", "nbgrader", *args], cwd=course, capture_output=True, text=True,
                         env=dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}"),
                         timeout=900)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out


def _functions(path: Path) -> dict[str, str]:
    """Each function of a corpus file with the file's imports and helpers (``_name``) above it: {name: source}."""
    text = path.read_text()
    tree = ast.parse(text)
    imports = "\n".join(ast.get_source_segment(text, n) for n in tree.body if isinstance(n, (ast.Import,
                                                                                              ast.ImportFrom)))
    defs = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
    helpers = "\n\n\n".join(ast.get_source_segment(text, n) for n in defs if n.name.startswith("_"))
    return {n.name: "\n\n\n".join(x for x in (imports, helpers, ast.get_source_segment(text, n)) if x)
            for n in defs if not n.name.startswith("_")}


def _solution_code(assignment: str) -> dict[str, str]:
    """The reference code of each exercise cell of the solution notebook (markers dropped)."""
    nb = json.loads((ROOT / "solutions" / f"{assignment}.ipynb").read_text())
    out = {}
    for c in nb["cells"]:
        if "exercise" in c["metadata"].get("tags", []):
            src = "".join(c["source"])
            name = ast.parse(src).body[0].name
            out[name] = "\n".join(line for line in src.splitlines() if "SOLUTION" not in line)
    return out


def _seeds() -> set[str]:
    checks = runpy.run_path(str(ROOT / "grading" / "cases.py"))["CHECKS"]
    return {str(spec["seed"]) for specs in checks.values() for spec in specs if "seed" in spec}  # precision: none


@pytest.fixture(scope="module")
def course(tmp_path_factory):
    try:
        import nbgrader  # noqa: F401
    except ImportError:
        missing("nbgrader is not installed (pip install -e '.[test]')")
    course = tmp_path_factory.mktemp("nbgrader") / "course"
    assert dtscal(["release", "--nbgrader", str(course)]) == 0
    for a in ASSIGNMENTS:
        _nbgrader(course, "generate_assignment", a)
    # the students' copies: nbgrader's release with their code in the solution cells
    for student, (a, files) in STUDENTS.items():
        nb = json.loads((course / "release" / a / f"{a}.ipynb").read_text())
        code = _solution_code(a)
        for f in files:
            code.update(_functions(f))
        for c in nb["cells"]:
            meta = c["metadata"].get("nbgrader", {})
            if meta.get("solution") and meta["grade_id"].startswith("solution_"):  # practice cells: left as stubs
                c["source"] = code[meta["grade_id"].removeprefix("solution_")]
        dest = course / "submitted" / student / a / f"{a}.ipynb"
        dest.parent.mkdir(parents=True)
        dest.write_text(json.dumps(nb))
    said = [_nbgrader(course, "autograde", a, "--create") for a in ASSIGNMENTS]
    (course / "autograde.log").write_text("".join(o.stdout + o.stderr for o in said))
    return course


def test_source_cells_carry_nbgrader_metadata(course):
    nb = json.loads((course / "source" / "02_homography" / "02_homography.ipynb").read_text())
    kinds = [c["metadata"]["nbgrader"] for c in nb["cells"]]
    assert all(k["schema_version"] == 3 for k in kinds)
    assert sorted(k["grade_id"] for k in kinds if k["solution"]) == ["solution_apply_homography",
                                                                     "solution_estimate_homography"]
    tests = [(k["grade_id"], k["points"]) for k in kinds if k["grade"]]
    assert tests == [("test_apply_homography", 10), ("test_estimate_homography", 10)]
    assert all(k["locked"] for k in kinds if not k["solution"])  # every other cell is read-only
    seeds = _seeds()
    for c in nb["cells"]:
        src = "".join(c["source"])
        if c["metadata"]["nbgrader"]["grade"]:  # the hidden cases sit between nbgrader's markers
            head, rest = src.split(HIDDEN[0])
            hidden, tail = rest.split(HIDDEN[1])
            assert any(s in hidden for s in seeds) and not any(s in head + tail for s in seeds)
        else:
            assert not any(s in src for s in seeds)


def test_students_copy_has_no_hidden_case_or_solution(course):
    seeds = _seeds()
    nb = json.loads((course / "release" / "02_homography" / "02_homography.ipynb").read_text())
    text = "\n".join("".join(c["source"]) for c in nb["cells"])
    assert not any(s in text for s in seeds) and HIDDEN[0] not in text
    sol = json.loads((ROOT / "solutions" / "02_homography.ipynb").read_text())
    region, inside = [], False  # the reference code: the lines between the solution markers
    for c in sol["cells"]:
        for line in "".join(c["source"]).splitlines():
            inside = (inside or "BEGIN SOLUTION" in line) and "END SOLUTION" not in line
            if inside and "SOLUTION" not in line and len(line.strip()) > 20:
                region.append(line.strip())
    assert len(region) > 10 and not [line for line in region if line in text]


def test_autograde_scores_agree_with_dtscal_grade_per_function(course, tmp_path):
    from nbgrader.api import Gradebook

    assert dtscal(["grade", str(course / "submitted"), "--csv", str(tmp_path / "g.csv"), "-q"]) == 0
    ours = {r["student"]: r for r in csv.DictReader(open(tmp_path / "g.csv"))}
    from dtscal_lib.grading.material import ASSIGNMENTS as FUNCS

    partial = 0
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gb:
        for student, (a, _files) in STUDENTS.items():
            for f in FUNCS[a]:
                g = gb.find_grade(f"test_{f}", a, a, student)
                assert g.max_score == 10
                assert g.score == pytest.approx(float(ours[student][f]), abs=0.011), (student, f)
                partial += 0 < g.score < g.max_score
    assert partial >= 1  # a partly right function keeps its partial points in nbgrader
    assert float(ours["alice"]["project_points"]) == 10 and float(ours["bob"]["project_points"]) < 10
    # erin's estimate_homography calls her wrong apply_homography: charged once, in apply_homography
    assert float(ours["erin"]["estimate_homography"]) == 10 and float(ours["erin"]["apply_homography"]) < 10


def test_export_refuses_a_foreign_folder(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    assert dtscal(["release", "--nbgrader", str(tmp_path)]) == 2
    assert "not an nbgrader course written by the kit" in capsys.readouterr().err


def test_export_carries_the_ungraded_notebooks_without_test_cells(tmp_path):
    """03b (split from 03 by issue 24) and 06 hold no exercise: exported read-only, with no autograded cell, except
    the student's own practice functions (issue 29), solution cells without points; 03 keeps its three graded
    functions."""
    assert dtscal(["release", "--nbgrader", str(tmp_path / "c")]) == 0
    src = tmp_path / "c" / "source"
    assert sorted(p.name for p in src.iterdir()) == sorted(p.stem for p in (ROOT / "solutions").glob("*.ipynb"))
    for name in ("03b_calibration_quality", "06_duckiebot_camera"):
        nb = json.loads((src / name / f"{name}.ipynb").read_text())
        meta = [c["metadata"].get("nbgrader", {}) for c in nb["cells"]]
        assert meta and not any(m.get("grade") or m.get("points") for m in meta), name
        solution = [m["grade_id"] for m in meta if m.get("solution")]
        assert solution and all(g.startswith("practice_") for g in solution), (name, solution)
    nb = json.loads((src / "03_intrinsic_calibration" / "03_intrinsic_calibration.ipynb").read_text())
    graded = sorted(c["metadata"]["nbgrader"]["grade_id"] for c in nb["cells"] if c["metadata"]["nbgrader"]["grade"])
    assert graded == ["test_extrinsics_from_homography", "test_intrinsic_constraints",
                      "test_intrinsics_from_homographies"]


def test_autogrades_checksum_warnings_are_nbgraders_own_hidden_tests_as_the_kit_explains(course, capsys):
    """Issue 32: real nbgrader's autograde prints "Attribute 'checksum' for cell test_... has changed!" for every
    autograded test cell of every student. It is nbgrader's own doing (jupyter/nbgrader#1961): generate_assignment
    stores a test cell's checksum with its hidden tests, the students' copy has them stripped, and autograde puts
    them back. The warnings name test cells only (never a student's solution cell, never a read-only course cell),
    and `dtscal release --nbgrader` and docs/ta.md say so, so that an instructor does not read them as tampering."""
    log = (course / "autograde.log").read_text()
    warned = re.findall(r"Attribute 'checksum' for cell (\S+) has changed", log)
    assert warned and all(cell.startswith("test_") for cell in warned), sorted(set(warned))
    again = course.parent / "again"
    assert dtscal(["release", "--nbgrader", str(again)]) == 0
    message = capsys.readouterr().err
    assert "Attribute 'checksum'" in message and "hidden tests" in message and "1961" in message, message
    assert "jupyter/nbgrader#1961" in (ROOT / "docs" / "ta.md").read_text()
