"""The Gradescope bundle: run_autograder grades a submission folder laid out as Gradescope's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile

import pytest

from dtscal_lib.cli import main as dtscal
from nbtools import ROOT, SOLUTIONS

CORPUS = ROOT / "tests" / "grading_corpus"


@pytest.fixture(scope="module")
def autograder(tmp_path_factory):
    base = tmp_path_factory.mktemp("gs")
    bundle = base / "autograder.zip"
    assert dtscal(["grade", "--gradescope-bundle", str(bundle)]) == 0
    root = base / "autograder"
    with zipfile.ZipFile(bundle) as z:
        names = z.namelist()
        z.extractall(root / "source")
    assert {"setup.sh", "run_autograder", "grading/cases.py", "pyproject.toml"} <= set(names)
    assert any(n.startswith("solutions/") for n in names) and any(n.startswith("dtscal_lib/grading/") for n in names)
    assert not any("__pycache__" in n for n in names)
    return root


def _run(root, files):
    sub = root / "submission"
    if sub.exists():
        for p in sub.iterdir():
            p.unlink()
    sub.mkdir(exist_ok=True)
    for name, data in files.items():
        (sub / name).write_bytes(data)
    env = dict(os.environ, DTSCAL_AUTOGRADER_ROOT=str(root), DTSCAL_PYTHON=sys.executable,
               PYTHONPATH=str(root / "source"))
    run = subprocess.run(["bash", str(root / "source" / "run_autograder")], env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    return json.loads((root / "results" / "results.json").read_text())


def test_run_autograder_grades_the_submission(autograder):
    res = _run(autograder, {
        "01_pinhole_projection.ipynb": (SOLUTIONS / "01_pinhole_projection.ipynb").read_bytes(),
        "02_homography.py": (CORPUS / "02_homography__apply_no_division.py").read_bytes(),
    })
    by_name = {t["name"]: t for t in res["tests"]}
    assert len(res["tests"]) == 6 + 11
    assert all(t["score"] == t["max_score"] for n, t in by_name.items() if n.startswith("01_pinhole_projection"))
    assert 10 <= res["score"] < 30
    failing = [t for n, t in by_name.items() if n.startswith("02_homography / apply") and t["score"] < t["max_score"]]
    assert failing and "no division when applying H" in failing[0]["output"]
    assert all(t["visibility"] == "visible" for t in res["tests"]) and res["execution_time"] > 0


def test_run_autograder_writes_results_for_an_unusable_submission(autograder):
    res = _run(autograder, {"notes.txt": b"I forgot my notebook"})
    assert res["score"] == 0 and "could not grade" in res["output"]


# --------------------------------------------------------------------------- a student's hand-in, whole path
def _student_handin(tmp_path):
    """A student's checkout: notebook 01 solved in workspace/ (plus a note of theirs), then `dtscal handin`."""
    import contextlib
    import io
    import shutil
    from unittest import mock

    import nbformat

    from dtscal_lib.teaching import release as rel
    from dtscal_lib.teaching import workspace as ws
    from nbtools import NOTEBOOKS

    root = tmp_path / "student"
    shutil.copytree(NOTEBOOKS, root / "notebooks")
    wsdir = ws.ensure_workspace(root)
    nb01 = wsdir / "01_pinhole_projection.ipynb"
    solved = rel.inject_solutions(nbformat.read(str(nb01), as_version=4),
                                  nbformat.read(str(SOLUTIONS / nb01.name), as_version=4))
    solved.cells.insert(1, nbformat.v4.new_markdown_cell("my notes"))
    nbformat.write(solved, str(nb01))
    (wsdir / "backups" / "old").mkdir(parents=True)
    shutil.copyfile(nb01, wsdir / "backups" / "old" / nb01.name)
    out = io.StringIO()
    with mock.patch("dtscal_lib.paths.repo_root", return_value=root), contextlib.redirect_stdout(out):
        assert dtscal(["handin", "--name", "Ada Lovelace"]) == 0
    z = root / "handin" / "Ada_Lovelace.zip"
    assert f"wrote {z} with 6 notebook(s)" in out.getvalue()
    with zipfile.ZipFile(z) as zf:
        assert sorted(zf.namelist()) == sorted(p.name for p in NOTEBOOKS.glob("*.ipynb"))  # nothing of the kit
        files = {n: zf.read(n) for n in zf.namelist()}
    return z, files


def _pinhole_full_marks(res):
    ours = [t for t in res["tests"] if t["name"].startswith("01_pinhole_projection")]
    assert ours and all(t["score"] == t["max_score"] for t in ours), ours
    assert not any(t["score"] for t in res["tests"] if not t["name"].startswith("01_pinhole_projection"))


def test_handin_zip_is_graded_by_dtscal_grade_and_by_the_gradescope_bundle(autograder, tmp_path):
    z, files = _student_handin(tmp_path)
    _pinhole_full_marks(_run(autograder, files))  # Gradescope unpacks the uploaded zip into submission/
    _pinhole_full_marks(_run(autograder, {z.name: z.read_bytes()}))  # the zip itself, if it arrives unpacked
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
