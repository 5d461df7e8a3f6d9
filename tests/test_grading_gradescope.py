"""The Gradescope bundle: run_autograder grades a submission folder laid out as Gradescope's."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import zipfile

import pytest
from handins import make_autograder, run_autograder, student_handin

from dtscal_lib.cli import main as dtscal
from nbtools import ROOT, SOLUTIONS, checks_of

CORPUS = ROOT / "tests" / "grading_corpus"


@pytest.fixture(scope="module")
def autograder(tmp_path_factory):
    return make_autograder(tmp_path_factory.mktemp("gs"))


def _run(root, files):
    return run_autograder(root, files)


def test_run_autograder_grades_the_submission(autograder):
    res = _run(autograder, {
        "01_pinhole_projection.ipynb": (SOLUTIONS / "01_pinhole_projection.ipynb").read_bytes(),
        "02_homography.py": (CORPUS / "02_homography__apply_no_division.py").read_bytes(),
    })
    by_name = {t["name"]: t for t in res["tests"]}
    assert len(res["tests"]) == checks_of("01_pinhole_projection") + checks_of("02_homography")
    assert all(t["score"] == t["max_score"] for n, t in by_name.items() if n.startswith("01_pinhole_projection"))
    assert 10 <= res["score"] < 30
    failing = [t for n, t in by_name.items() if n.startswith("02_homography / apply") and t["score"] < t["max_score"]]
    assert failing and "no division when applying H" in failing[0]["output"]
    assert all(t["visibility"] == "visible" for t in res["tests"]) and res["execution_time"] > 0


def test_run_autograder_writes_results_for_an_unusable_submission(autograder):
    res = _run(autograder, {"notes.txt": b"I forgot my notebook"})
    assert res["score"] == 0 and "could not grade" in res["output"]


GRADER_FAILS = """#!/usr/bin/env bash
# stands in for the kit's Python: dtscal grade as it ends when the grader itself failed (exit status 3)
while [ $# -gt 0 ]; do [ "$1" = --json ] && out="$2"; shift; done
echo '{"extra_data": {"status": "grader error", "autograder_failed": true}, "output": "x", "tests": []}' > "$out"
exit 3
"""


def test_a_grader_error_is_an_autograder_failure_on_gradescope(autograder, tmp_path):
    """Gradescope shows "The autograder failed to execute correctly" when results.json is missing
    (its Troubleshooting page): run_autograder withholds it when the grader failed, never a 0."""
    fake = tmp_path / "python"
    fake.write_text(GRADER_FAILS)
    fake.chmod(0o755)
    results = autograder / "results"
    shutil.rmtree(results, ignore_errors=True)
    (autograder / "submission").mkdir(exist_ok=True)
    env = dict(os.environ, DTSCAL_AUTOGRADER_ROOT=str(autograder), DTSCAL_PYTHON=str(fake))
    run = subprocess.run(["bash", str(autograder / "source" / "run_autograder")], env=env, capture_output=True,
                         text=True, timeout=60)
    assert run.returncode != 0 and "grader error" in run.stderr, run.stderr
    assert not (results / "results.json").exists()
    assert json.loads((results / "not-graded.json").read_text())["extra_data"]["autograder_failed"]


# --------------------------------------------------------------------------- a student's hand-in, whole path
def _student_handin(tmp_path):
    """A student's checkout: notebook 01 solved in workspace/ (plus a note of theirs), then `dtscal handin`."""
    z = student_handin(tmp_path, "Ada Lovelace")
    with zipfile.ZipFile(z) as zf:
        files = {n: zf.read(n) for n in zf.namelist()}
    return z, files


def _pinhole_full_marks(res):
    ours = [t for t in res["tests"] if t["name"].startswith("01_pinhole_projection")]
    assert ours and all(t["score"] == t["max_score"] for t in ours), ours
    assert not any(t["score"] for t in res["tests"] if not t["name"].startswith("01_pinhole_projection"))


def test_handin_zip_is_graded_by_dtscal_grade_and_by_the_gradescope_bundle(autograder, tmp_path):
    z, files = _student_handin(tmp_path)
    _pinhole_full_marks(_run(autograder, files))  # Gradescope unpacks the uploaded zip into submission/
    res = _run(autograder, {z.name: z.read_bytes()})  # the zip itself, if it arrives unpacked
    _pinhole_full_marks(res)
    assert f"{z.name}: not a notebook" not in res["output"]  # graded, not called "not a notebook"
    assert not list((autograder / "submission").glob("*.ipynb"))  # read with caps, never unpacked to disk
    out = tmp_path / "results.json"
    assert dtscal(["grade", str(z), "--json", str(out), "-q"]) == 0  # the instructor, on the file as handed in
    _pinhole_full_marks(json.loads(out.read_text()))


def test_setup_sh_refuses_a_python_older_than_3_11_and_names_the_base_image(autograder, tmp_path):
    """Gradescope's default image (Ubuntu 22.04) has Python 3.10: setup.sh says which base image to choose."""
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "apt-get").write_text("#!/bin/sh\nexit 0\n")
    for name in ("python3", "python3.11", "python3.12", "python3.13"):
        (fake / name).write_text('#!/bin/sh\ncase "$*" in *--version*) echo "Python 3.10.12";; *) exit 1;; esac\n')
    for p in fake.iterdir():
        p.chmod(0o755)
    env = dict(os.environ, PATH=f"{fake}:/usr/bin:/bin", DTSCAL_AUTOGRADER_ROOT=str(tmp_path / "ag"))
    run = subprocess.run(["bash", str(autograder / "source" / "setup.sh")], env=env, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 1
    assert "needs Python 3.11 or newer, but this image has Python 3.10.12" in run.stderr
    assert "choose the base image Ubuntu 24.04" in run.stderr and "Traceback" not in run.stderr
    assert not (tmp_path / "ag" / "venv").exists()
