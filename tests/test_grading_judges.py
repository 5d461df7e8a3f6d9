"""The judges' rules, each on answers built here to sit on either side of the rule (issue 22: planted one at
a time, these bugs passed the grading tests): noisy-H credit per case, the tolerance ``atol + rtol * |w|``, the
1.25x margin over the accepted formulations' largest error, and the references cross-checked against OpenCV
and the ground truth before anything is judged."""

from __future__ import annotations

import json
import runpy

import numpy as np
import pytest

from dtscal_lib.grading.checks import Built, MaterialError, build_check, judge_close
from dtscal_lib.grading.material import ASSIGNMENTS, Material
from dtscal_lib.grading.sandbox import Call, CheckRun
from nbtools import ROOT

CASES = runpy.run_path(str(ROOT / "grading" / "cases.py"))["CHECKS"]
#: the margin over the largest error of the accepted formulations, as issue 22 and the README (Grading) state it
MARGIN = 1.25


@pytest.fixture(scope="module")
def material():
    return Material.load(ROOT)


def _run(*values):
    return CheckRun(calls=[Call(ok=True, value=v) for v in values])


def _noisy_H(material) -> Built:
    return next(b for b in material.checks("02_homography")["estimate_homography"]
                if b.judge.__name__ == "judge_truth_H" and len(b.calls) > 1)


def _shifted(H, dx):
    """``H`` followed by a shift of ``dx`` pixels along u: every mapped point moves by exactly ``dx``, so the
    RMS distance from ``H``'s points is ``dx``."""
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ H


def test_noisy_homography_gets_credit_per_case(material):
    b = _noisy_H(material)
    truth = b.extra["truth"]
    limit = b.extra["tolerance"]["tolerance"]["truth_rms_px"]
    answers = [_shifted(truth[0], 3 * limit)] + [H.copy() for H in truth[1:]]
    frac, why = b.judge(b, _run(*answers))
    assert frac == pytest.approx((len(truth) - 1) / len(truth))  # one case of n wrong: (n - 1) / n of the points
    assert "case 1:" in why and "case 2:" not in why


def test_noisy_homography_limit_keeps_the_margin(material):
    b = _noisy_H(material)
    stored = json.loads((ROOT / "grading" / "tolerances.json").read_text())
    entry = next(v for v in stored.values() if v["check"] == b.name or v["tolerance"] == b.extra["tolerance"]
                 ["tolerance"])
    worst = entry["max"]["truth_rms_px"]  # the largest error of every accepted formulation on 10000 draws
    assert entry["margin"] == MARGIN
    truth = b.extra["truth"]
    inside = [_shifted(H, 1.15 * worst) for H in truth]  # past the formulations' worst, within the margin
    outside = [_shifted(H, 1.3 * worst) for H in truth]
    assert b.judge(b, _run(*inside))[0] == 1.0
    assert b.judge(b, _run(*outside))[0] == 0.0


def test_tolerance_adds_atol_and_rtol_times_the_largest_value():
    """``|got - want| <= atol + rtol * max|want|`` (numpy.isclose's sum, on the array's scale): with
    atol = rtol = 1e-6 and max|want| = 1, an error of 1.5e-6 passes (it would fail max(atol, rtol * |w|))."""
    want = np.array([[1.0, -0.5], [0.25, 0.0]])
    b = Built("apply_homography", "t", 1.0, [("apply_homography", ())], [want], judge_close,
              {"atol": 1e-6, "rtol": 1e-6})
    assert b.judge(b, _run(want + 1.5e-6))[0] == 1.0
    assert b.judge(b, _run(want + 2.5e-6))[0] == 0.0


@pytest.mark.parametrize("func", ["project_points", "apply_homography", "distort_normalized",
                                  "board_ground_points"])
def test_a_wrong_reference_is_refused_before_anything_is_judged(material, func):
    """The solution notebook's function must agree with the independent reference (OpenCV or the truth the
    case was built from): a reference off by 1e-3 is the instructor's error, said before any student's grade."""
    spec = next(s for s in CASES[func] if s.get("judge", "close") == "close")
    assignment = next(a for a, fs in ASSIGNMENTS.items() if func in fs)
    from dtscal_lib.grading.material import reference_functions

    good = reference_functions(ROOT / "solutions" / f"{assignment}.ipynb", ASSIGNMENTS[assignment])[func]
    build_check(func, spec, good, material.tolerances)  # the real one passes

    def off(*args):
        out = good(*args)
        return tuple(np.asarray(o, float) + 1e-3 for o in out) if isinstance(out, tuple) else \
            np.asarray(out, float) + 1e-3

    with pytest.raises(MaterialError, match="disagrees with the independent reference"):
        build_check(func, spec, off, material.tolerances)
