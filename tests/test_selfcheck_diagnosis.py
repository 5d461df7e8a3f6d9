"""Self-checks of notebooks 01 and 02 fed wrong answers: they fail, name the mistake first
(one line, with the activity-text equation), print plain numbers, and pass right answers."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from dtscal_lib.teaching.release import solution_functions
from dtscal_lib import mistakes as diagnosis
from dtscal_lib.teaching.selfcheck import check_apply_homography, check_estimate_homography, check_project_points
from nbtools import SOLUTIONS

CORPUS = Path(__file__).parent / "grading_corpus"
CHECKS = {"project_points": check_project_points, "apply_homography": check_apply_homography,
          "estimate_homography": check_estimate_homography}
#: corpus mistakes the self-checks catch by a failing case, not by a diagnosis model
NO_MODEL = {"squeeze", "modifies_input", "float32"}


def _load(path: Path) -> dict:
    ns: dict = {}
    exec(compile(path.read_text(), str(path), "exec"), ns)
    return ns


def _wrong_answers():
    for p in sorted(CORPUS.glob("0[12]_*.py")):
        ns = _load(p)
        key = re.search(r"# mistake: (\w+)", p.read_text()).group(1)
        func = "project_points" if p.name.startswith("01") else \
            "apply_homography" if "__apply_" in p.name else "estimate_homography"
        yield pytest.param(ns[func], func, key, id=p.stem)


@pytest.mark.parametrize("fn, func, key", list(_wrong_answers()))
def test_wrong_answer_fails_and_is_named(capsys, fn, func, key):
    report = CHECKS[func](fn)
    shown = capsys.readouterr().out
    assert report.status == "fail"
    assert "np.float64" not in shown
    if key in NO_MODEL:
        return
    assert report.diagnosis.startswith("diagnosis: ") and "activity text, eq." in report.diagnosis
    mistake = diagnosis.diagnose_function(func, fn)
    assert mistake is not None
    lines = shown.splitlines()
    assert lines[1].strip() == report.diagnosis  # first, before the case list
    assert "hint:" not in shown  # the diagnosis replaces the generic hints


@pytest.mark.parametrize("nb, func", [("01_pinhole_projection", "project_points"),
                                      ("02_homography", "apply_homography"),
                                      ("02_homography", "estimate_homography")])
def test_right_answer_passes_without_diagnosis(capsys, nb, func):
    fn = solution_functions(SOLUTIONS / f"{nb}.ipynb", [func])[func]
    report = CHECKS[func](fn)
    assert report.passed and not report.diagnosis
    assert diagnosis.diagnose_function(func, fn) is None


def test_every_function_has_probes_and_models():
    for func in diagnosis.FUNCTIONS:
        assert diagnosis.probe_args(func)
        right, models = diagnosis.MISTAKES[func]
        assert models


def test_no_perspective_division_no_longer_points_elsewhere(capsys):
    """The issue's example: a missing division used to fail 6/6 with hints about row order and skew."""
    report = check_project_points(lambda K, R, t, X: ((X @ R.T + t) @ K.T)[:, :2])
    out = capsys.readouterr().out
    assert "no perspective division" in out.splitlines()[1]
    assert "skew" not in out.split("diagnosis:")[1].split("\n")[0]
    assert report.status == "fail"


def test_strict_mode_raises(monkeypatch, capsys):
    from dtscal_lib.teaching.selfcheck import SelfCheckFailed

    def stub(K, R, t, X):
        raise NotImplementedError

    check_project_points(stub)  # not strict: prints, returns
    monkeypatch.setenv("DTSCAL_STRICT", "1")
    with pytest.raises(SelfCheckFailed, match="not implemented"):
        check_project_points(stub)
    with pytest.raises(SelfCheckFailed, match="no perspective division"):
        check_project_points(lambda K, R, t, X: ((X @ R.T + t) @ K.T)[:, :2])
    fn = solution_functions(SOLUTIONS / "01_pinhole_projection.ipynb", ["project_points"])["project_points"]
    assert check_project_points(fn).passed
    monkeypatch.setenv("DTSCAL_STRICT", "0")
    check_project_points(stub)
    assert np.isfinite(1.0)
