"""The grader on real course material: solutions, untouched student notebooks, the buggy corpus,
the loader (only imports and defs run) and the academic-honesty rule."""

from __future__ import annotations

import csv
import json
import re
import textwrap
from pathlib import Path

import pytest

from dtscal_lib.cli import main as dtscal
from dtscal_lib.grading.classroom import discover, grade_all
from dtscal_lib.grading import grade as grade_module
from dtscal_lib.grading.grade import grade_file
from dtscal_lib.grading.loader import forbidden_calls, load_submission
from dtscal_lib.grading.material import ASSIGNMENTS, Material
from dtscal_lib.grading.report import gradescope, text
from nbtools import NOTEBOOKS, ROOT, SOLUTIONS

CORPUS = Path(__file__).parent / "grading_corpus"


@pytest.fixture(scope="module")
def material():
    return Material.load(ROOT)


@pytest.mark.parametrize("assignment", list(ASSIGNMENTS))
def test_solution_scores_full_marks(material, assignment):
    res = grade_file(SOLUTIONS / f"{assignment}.ipynb", material, assignment)
    assert res.max_score == 10 * len(ASSIGNMENTS[assignment])
    assert res.score == res.max_score, text(res)
    assert not any(f.diagnosis for f in res.functions)


@pytest.mark.parametrize("assignment", list(ASSIGNMENTS))
def test_untouched_student_notebook_scores_zero_without_a_sandbox(material, assignment, monkeypatch):
    material.checks(assignment)
    started = []
    monkeypatch.setattr(grade_module, "run_calls", lambda *a, **k: started.append(a) or pytest.fail("sandbox started"))
    res = grade_file(NOTEBOOKS / f"{assignment}.ipynb", material, assignment)
    assert res.score == 0
    assert all(f.status == "not implemented" for f in res.functions)
    assert all(t.output.startswith("not implemented") for f in res.functions for t in f.tests)
    assert started == []  # stubs are recognised without starting a sandbox (an event, not a time)


# --------------------------------------------------------------------------- the corpus
def _corpus_items():
    return sorted(CORPUS.glob("*.py"))


@pytest.fixture(scope="module")
def corpus_results(material):
    items, skipped = discover(CORPUS)
    assert not skipped
    return {Path(r.submission).name: r for r in grade_all(items, material, jobs=2)}


def test_corpus_is_big_enough():
    files = _corpus_items()
    assert len(files) >= 30
    for a in ASSIGNMENTS:
        assert sum(f.name.startswith(a) for f in files) >= 5, a
    keys = {re.search(r"# mistake: (\w+)", f.read_text()).group(1) for f in files}
    assert len(keys) >= 30


@pytest.mark.parametrize("path", _corpus_items(), ids=lambda p: p.stem)
def test_corpus_scores_below_full_and_names_the_mistake(corpus_results, path):
    res = corpus_results[path.name]
    expect = re.search(r"# expect: (.*)", path.read_text()).group(1).strip()
    assert res.score < res.max_score
    report = text(res)
    assert expect in report, report
    # the diagnosis, when there is one, comes before the list of checks of its function
    for f in res.functions:
        if f.diagnosis:
            block = report[report.index(f"  {f.name}:"):]
            assert block.index("diagnosis:") < block.index(f.tests[0].name)
            assert "activity text" in f.diagnosis


def test_feedback_numbers_are_plain(corpus_results):
    for res in corpus_results.values():
        assert "np.float64" not in text(res)


# --------------------------------------------------------------------------- loader
def _write(tmp_path, name, src):
    p = tmp_path / name
    p.write_text(textwrap.dedent(src))
    return p


def test_only_imports_and_defs_run(tmp_path, material):
    marker = tmp_path / "top_level_ran"
    sub = _write(tmp_path, "01_pinhole_projection.py", f"""
        import sys
        import numpy as np
        open({str(marker)!r}, "w").write("x")
        for _ in range(10 ** 12):
            pass
        sys.exit(3)

        def project_points(K, R, t, X):
            x = (np.asarray(X) @ R.T + t) @ K.T
            return x[:, :2] / x[:, 2:]
        raise SystemExit("top-level code must not run")
        """)
    parsed = load_submission(sub)
    assert parsed.dropped == 4 and list(parsed.functions) == ["project_points"]
    res = grade_file(sub, material, "01_pinhole_projection")
    assert res.score == res.max_score, text(res)
    assert not marker.exists()


def test_notebook_cells_and_magics(tmp_path, material):
    src = json.loads((SOLUTIONS / "01_pinhole_projection.ipynb").read_text())
    src["cells"].insert(2, {"cell_type": "code", "metadata": {}, "outputs": [], "execution_count": None,
                            "source": ["%matplotlib inline\n", "!rm -rf /\n", "def helper(x):\n", "    return x\n"]})
    src["cells"].insert(3, {"cell_type": "code", "metadata": {}, "outputs": [], "execution_count": None,
                            "source": ["this is not python("]})
    p = tmp_path / "01_pinhole_projection.ipynb"
    p.write_text(json.dumps(src))
    res = grade_file(p, material, "01_pinhole_projection")
    assert res.score == res.max_score, text(res)
    assert any("syntax error" in n for n in res.notes)


# --------------------------------------------------------------------------- academic honesty
HONESTY = {
    "direct": "import cv2\ndef project_points(K, R, t, X):\n"
              "    return cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, None)[0].reshape(-1, 2)\n",
    "from_alias": "from cv2 import projectPoints as pp\nimport cv2\ndef project_points(K, R, t, X):\n"
                  "    return pp(X, cv2.Rodrigues(R)[0], t, K, None)[0].reshape(-1, 2)\n",
    "module_alias": "import cv2 as c\ndef project_points(K, R, t, X):\n"
                    "    return c.projectPoints(X, c.Rodrigues(R)[0], t, K, None)[0].reshape(-1, 2)\n",
    "getattr": "import cv2\ndef project_points(K, R, t, X):\n    f = getattr(cv2, 'projectPoints')\n"
               "    return f(X, cv2.Rodrigues(R)[0], t, K, None)[0].reshape(-1, 2)\n",
    "kit": "from dtscal_lib import camera as cam\ndef project_points(K, R, t, X):\n"
           "    return cam.CameraModel(K, None).project(X, R, t)\n",
    "kit_submodule": "import dtscal_lib.homography as h\ndef project_points(K, R, t, X):\n    return h.apply(K, X)\n",
    "local_import": "def project_points(K, R, t, X):\n    from cv2 import projectPoints\n"
                    "    return projectPoints(X, R, t, K, None)[0].reshape(-1, 2)\n",
    "via_helper": "import cv2\ndef _cv(K, R, t, X):\n"
                  "    return cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, None)[0]\n"
                  "def project_points(K, R, t, X):\n    return _cv(K, R, t, X).reshape(-1, 2)\n",
}


@pytest.mark.parametrize("kind", list(HONESTY))
def test_solving_routines_get_no_credit(tmp_path, material, kind):
    sub = _write(tmp_path, "01_pinhole_projection.py", HONESTY[kind])
    res = grade_file(sub, material, "01_pinhole_projection")
    f = res.functions[0]
    assert res.score == 0 and f.status == "academic honesty"
    assert "no credit" in f.tests[0].output and "does the exercise for you" in f.tests[0].output


def test_opencv_in_plots_and_allowed_helpers_is_fine(tmp_path, material):
    sub = _write(tmp_path, "01_pinhole_projection.py", """
        import cv2
        import numpy as np
        from dtscal_lib import duckietown

        def show(K, R, t, X):  # a plot helper, not an exercise function
            return cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, None)[0]

        def project_points(K, R, t, X):
            _ = duckietown.IMAGE_SIZE
            x = (np.asarray(X) @ R.T + t) @ K.T
            return x[:, :2] / x[:, 2:]
        """)
    res = grade_file(sub, material, "01_pinhole_projection")
    assert res.score == res.max_score, text(res)


def test_forbidden_calls_names_the_routine():
    import ast

    tree = ast.parse("import numpy as np\nfrom cv2 import findHomography as fh\n"
                     "def f(a, b):\n    np.linalg.svd(a)\n    return fh(a, b)\n")
    aliases = {"np": "numpy", "fh": "cv2.findHomography"}
    assert forbidden_calls(tree.body[2], aliases) == ["cv2.findHomography"]


# --------------------------------------------------------------------------- command line
def test_cli_writes_gradescope_json_and_csv(tmp_path, capsys):
    cls = tmp_path / "class"
    (cls / "ada").mkdir(parents=True)
    (cls / "bo").mkdir()
    (cls / "ada" / "01_pinhole_projection.ipynb").write_bytes((SOLUTIONS / "01_pinhole_projection.ipynb").read_bytes())
    (cls / "ada" / "05_extrinsic_calibration.py").write_text((CORPUS / "05_extrinsic_calibration__from_left.py")
                                                             .read_text())
    (cls / "bo" / "01_pinhole_projection.ipynb").write_bytes((NOTEBOOKS / "01_pinhole_projection.ipynb").read_bytes())
    out_json, out_csv = tmp_path / "r.json", tmp_path / "s.csv"
    assert dtscal(["grade", str(cls), "--jobs", "2", "--json", str(out_json), "--csv", str(out_csv), "-q"]) == 0
    data = json.loads(out_json.read_text())["students"]
    assert 10 <= data["ada"]["score"] < 20 and data["bo"]["score"] == 0
    for t in data["ada"]["tests"]:
        assert set(t) == {"name", "score", "max_score", "output", "visibility"}
    rows = list(csv.reader(out_csv.read_text().splitlines()))
    assert rows[0] == ["student", "project_points", "board_ground_points", "pixel_to_ground", "camera_height_pitch",
                       "total", "max", "notes"]
    ada, bo = rows[1], rows[2]
    assert ada[0] == "ada" and ada[1] == "10" and float(ada[2]) < 10 and ada[3] == "0" and ada[4] == "0"
    assert ada[6] == "40"
    # the same maximum for everyone; what was not handed in is 0, and says so
    assert bo[:7] == ["bo", "0", "0", "0", "0", "0", "40"] and "05_extrinsic_calibration: not handed in" in bo[7]


def test_cli_single_notebook_table(tmp_path, capsys):
    out = tmp_path / "results.json"
    assert dtscal(["grade", str(CORPUS / "01_pinhole_projection__no_division.py"), "--json", str(out)]) == 0
    shown = capsys.readouterr().out
    first_check = shown.index("noise-free pixels")
    assert 0 < shown.index("diagnosis: no perspective division") < first_check
    res = json.loads(out.read_text())
    assert 0 <= res["score"] < 10 and res["execution_time"] > 0
    assert sum(t["max_score"] for t in res["tests"]) == 10


@pytest.mark.parametrize("argv, message", [
    (["grade", "nope.ipynb"], "does not exist"),
    (["grade", "README.md"], "is not a notebook"),
    (["grade"], "give a submission"),
    (["grade", "solutions/01_pinhole_projection.ipynb", "--assignment", "07"], "unknown assignment"),
])
def test_cli_bad_input_is_a_clear_error(capsys, monkeypatch, argv, message):
    monkeypatch.chdir(ROOT)
    assert dtscal(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_gradescope_json_carries_the_diagnosis(corpus_results):
    res = corpus_results["02_homography__apply_no_division.py"]
    gs = gradescope([res])
    failing = [t for t in gs["tests"] if t["score"] < t["max_score"]]
    assert failing and all(t["output"].startswith("diagnosis: no division when applying H") for t in failing
                           if t["name"].startswith("apply_homography"))
