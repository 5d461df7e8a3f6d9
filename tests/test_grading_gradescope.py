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
