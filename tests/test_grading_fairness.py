"""The grader wrongs no correct student: correct variants get full marks, noisy checks are
judged against the truth with tolerances derived from the accepted formulations (and
fail correct code on fewer than 1 draw in 1000), one bug costs one function, code that
computes nothing scores 0, and the scores of known partial submissions are pinned."""

from __future__ import annotations

import re
import runpy
import textwrap
from pathlib import Path

import numpy as np
import pytest

from dtscal_lib.grading import checks, substitutes, tolerances
from dtscal_lib.grading.classroom import discover, grade_all
from dtscal_lib.grading.grade import FORM_GATED, grade_file
from dtscal_lib.grading.material import ASSIGNMENTS, Material
from dtscal_lib.grading.report import text
from dtscal_lib.grading.sandbox import Call, CheckRun
from nbtools import ROOT

CORRECT = Path(__file__).parent / "grading_corpus_correct"
MISTAKES = Path(__file__).parent / "grading_corpus"
CASES = runpy.run_path(str(ROOT / "grading" / "cases.py"))["CHECKS"]


@pytest.fixture(scope="module")
def material():
    return Material.load(ROOT)


@pytest.fixture(scope="module")
def correct_results(material):
    items, skipped = discover(CORRECT)
    assert not skipped
    return {Path(r.submission).name: r for r in grade_all(items, material, jobs=2)}


@pytest.fixture(scope="module")
def mistake_results(material):
    items, _ = discover(MISTAKES)
    return {Path(r.submission).stem: r for r in grade_all(items, material, jobs=2)}


# --------------------------------------------------------------------------- correct variants
def test_correct_corpus_covers_every_function_and_formulation():
    files = sorted(CORRECT.glob("*.py"))
    assert len(files) >= 30
    defined = {f: 0 for fs in ASSIGNMENTS.values() for f in fs}
    for p in files:
        for name in re.findall(r"^def (\w+)\(", p.read_text(), re.M):
            if name in defined:
                defined[name] += 1
    assert min(defined.values()) >= 5, defined
    text_ = "\n".join(p.read_text() for p in files)
    # every formulation the activity text or a textbook uses, and the tolerances' formulations
    for words in ("H as given", "H / H[2, 2]", "spectral norm", "Frobenius norm", "rows of V normalized",
                  "eigh of V^T V", "Cholesky of B", "lambda = 1 / |K^-1 h1|", "lambda from the mean",
                  "geometric mean", "normalized separately", "Hartley sqrt(2) mean distance", "RMS distance",
                  "per-axis standardization", "bounding box", "eigenvector of A^T A", "Horner", "numerical Jacobian",
                  "fixed point then Newton"):
        assert words in text_, words


@pytest.mark.parametrize("path", sorted(CORRECT.glob("*.py")), ids=lambda p: p.stem)
def test_correct_variant_gets_full_marks(correct_results, path):
    res = correct_results[path.name]
    assert res.max_score == 10 * len(ASSIGNMENTS[res.assignment])
    assert res.score == res.max_score, text(res)
    assert not any(f.diagnosis for f in res.functions), text(res)


@pytest.mark.parametrize("path", sorted(CORRECT.glob("*.py"))[::3], ids=lambda p: p.stem)
def test_public_self_checks_agree_that_correct_variants_are_correct(path):
    import dtscal_lib.teaching.selfcheck as sc

    ns = runpy.run_path(str(path))
    assignment = next(a for a in ASSIGNMENTS if path.name.startswith(a))
    for func in ASSIGNMENTS[assignment]:
        report = getattr(sc, f"check_{func}")(ns[func])
        assert report.passed, report.text()


# --------------------------------------------------------------------------- tolerances vs truth
def _noisy_specs():
    return tolerances.noisy_specs(CASES)


def test_every_noisy_check_is_judged_against_the_truth_with_a_stored_tolerance():
    stored = tolerances.load(ROOT)
    specs = _noisy_specs()
    assert {f for f, _ in specs} == set(tolerances.FORMULATIONS)
    for func, spec in specs:
        tol = stored[tolerances.shape_key(func, spec)]
        assert tol["seeds"] >= 1000 and tol["margin"] > 1
        assert set(tol["per_formulation_max"]) == set(tolerances.FORMULATIONS[func])
        for stat, v in tol["tolerance"].items():
            assert tol["margin"] * tol["max"][stat] <= v <= tol["margin"] * tol["max"][stat] * 1.01
    # the old judges (compared with the reference's own noisy estimate) are gone
    assert "transfer" not in checks.JUDGES and "pose" not in checks.JUDGES


def _false_failures(func, spec, seeds, seed0):
    """Draws (of ``seeds``) on which some accepted formulation exceeds the stored tolerance."""
    tol = tolerances.load(ROOT)[tolerances.shape_key(func, spec)]["tolerance"]
    limits = {"truth_rms_px": tol.get("truth_rms_px"), "K_max_px": tol.get("K_max_px"), "deg": tol.get("deg"),
              "t_rel": tol.get("t_rel")}
    bad = 0
    for k in range(seeds):
        args_list, truth = checks.inputs_and_truth(func, spec, np.random.default_rng(seed0 + k))
        worst = False
        for f in tolerances.FORMULATIONS[func].values():
            for e in tolerances.errors_of(func, f, args_list, truth):
                worst |= "failed" in e or any(v > limits[s] for s, v in e.items())
        bad += worst
    return bad


@pytest.mark.parametrize("func, spec", _noisy_specs(), ids=lambda x: x if isinstance(x, str) else x["name"][:30])
def test_false_failure_rate_fresh_draws(func, spec):
    # 300 fresh draws (seeds never used to derive the tolerance), every accepted formulation on
    # each: no failure. Binomial argument: were the per-draw false-failure rate 1 % or more,
    # 0 failures in 300 draws would happen with probability <= 0.99**300 = 4.9 %.
    assert _false_failures(func, spec, 300, 20_000_000) == 0


@pytest.mark.slow
@pytest.mark.parametrize("func, spec", _noisy_specs(), ids=lambda x: x if isinstance(x, str) else x["name"][:30])
def test_false_failure_rate_below_one_in_a_thousand(func, spec):
    # 3000 fresh draws: were the rate 1/1000 or more, 0 failures would happen with probability
    # <= 0.999**3000 = 5.0 %.
    assert _false_failures(func, spec, 3000, 30_000_000) == 0


def test_unnormalized_dlt_fails_the_conditioning_check():
    # a wrong formulation (no Hartley normalization) fails the check near 20000 on the case (the
    # mistakes corpus) and on most draws of its 2 views (measured: 62 of 100)
    func, spec = next((f, s) for f, s in _noisy_specs() if s.get("offset"))
    limit = tolerances.load(ROOT)[tolerances.shape_key(func, spec)]["tolerance"]["truth_rms_px"]

    def raw(s, d):
        return tolerances._dlt(s, d, lambda p: np.eye(3))

    fails = 0
    for k in range(100):
        args_list, truth = checks.inputs_and_truth(func, spec, np.random.default_rng(40_000_000 + k))
        fails += any(e["truth_rms_px"] > limit for e in tolerances.errors_of(func, raw, args_list, truth))
    assert fails >= 50


def _run(*values):
    return CheckRun(calls=[Call(ok=True, value=v) for v in values])


def _built(material, func, check_name_start):
    assignment = next(a for a, fs in ASSIGNMENTS.items() if func in fs)
    return next(b for b in material.checks(assignment)[func] if b.name.startswith(check_name_start))


def _rot(axis, deg):
    import cv2

    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return cv2.Rodrigues(axis * np.deg2rad(deg))[0]


def test_pose_tolerance_is_in_degrees(material):
    b = _built(material, "extrinsics_from_homography", "noisy homographies")
    max_deg = b.extra["tolerance"]["tolerance"]["deg"]
    assert 1 < max_deg < 30  # degrees (the same number in radians would be 57x looser)
    truth = b.extra["truth"]
    inside = [(_rot([0, 1, 0.3], 0.8 * max_deg) @ R, t) for R, t in truth]
    outside = [(_rot([0, 1, 0.3], 1.2 * max_deg) @ R, t) for R, t in truth]
    assert b.judge(b, _run(*inside))[0] == 1.0
    frac, why = b.judge(b, _run(*outside))
    assert frac == 0.0 and "deg" in why and "true pose" in why


def test_noisy_K_is_judged_against_the_true_K(material):
    b = _built(material, "intrinsics_from_homographies", "12 noisy views")
    K_true = b.extra["truth"][0]
    limit = b.extra["tolerance"]["tolerance"]["K_max_px"]
    assert b.judge(b, _run(K_true.copy()))[0] == 1.0
    off = K_true.copy()
    off[0, 2] += 1.1 * limit
    frac, why = b.judge(b, _run(off))
    assert frac == 0.0 and "cx" in why and "true K" in why and f"{tolerances.SEEDS} noise draws" in why
    # the reference's own noisy estimate is not the yardstick: it is several px from the truth
    assert tolerances.K_max_px(b.refs[0], K_true) > 1.0


# --------------------------------------------------------------------------- one bug, one charge
def _swap_function(src: str, name: str, new_def: str) -> str:
    start = src.index(f"def {name}(")
    nxt = re.search(r"^def \w+\(", src[start + 4:], re.M)
    end = start + 4 + nxt.start() if nxt else len(src)
    return src[:start] + new_def.strip() + "\n\n\n" + src[end:]


def test_wrong_callee_is_charged_once(tmp_path, material):
    good = (CORRECT / "04_distortion_rectification__plain_newton_inv.py").read_text()
    wrong = (MISTAKES / "04_distortion_rectification__radial_in_r.py").read_text()
    wrong_def = wrong[wrong.index("def distort_normalized("):]
    sub = tmp_path / "04_distortion_rectification.py"
    sub.write_text(_swap_function(good, "distort_normalized", wrong_def))
    res = grade_file(sub, material, "04_distortion_rectification")
    scores = {f.name: f.score for f in res.functions}
    assert scores == {"distort_normalized": 0, "undistort_normalized": 10, "rectification_maps": 10}, text(res)
    notes = "\n".join(res.notes)
    assert "undistort_normalized calls distort_normalized, which lost points: graded with the grader's " \
           "distort_normalized" in notes
    assert "With your own distort_normalized, undistort_normalized would score 4.4 / 10 instead of 10." in notes
    assert "With your own distort_normalized, rectification_maps would score 4 / 10 instead of 10." in notes


def test_right_callee_is_used_as_is(material):
    res = grade_file(CORRECT / "04_distortion_rectification__plain_newton_inv.py", material,
                     "04_distortion_rectification")
    assert res.score == 30
    assert "undistort_normalized calls distort_normalized, which passes all its checks: graded with yours." \
        in res.notes


def test_stand_ins_agree_with_opencv():
    import cv2

    ns: dict = {}
    for name in substitutes.SUBSTITUTES:
        exec(substitutes.source(name), ns)  # as the sandbox runs them
    rng = np.random.default_rng(5)
    xy, d = rng.uniform(-0.8, 0.8, (50, 2)), np.array([-0.25, 0.07, 0.01, -0.02, -0.01])
    want = cv2.projectPoints(np.column_stack([xy, np.ones(50)]), np.zeros(3), np.zeros(3), np.eye(3), d)[0]
    np.testing.assert_allclose(ns["distort_normalized"](xy, d), want.reshape(-1, 2), atol=1e-12)
    H = rng.normal(size=(3, 3))
    np.testing.assert_allclose(ns["apply_homography"](H, xy),
                               cv2.perspectiveTransform(xy.reshape(-1, 1, 2), H).reshape(-1, 2), rtol=1e-10)
    assert ns["intrinsic_constraints"](H).shape == (2, 6)
    np.testing.assert_allclose(ns["board_ground_points"](3, 2, 0.1, 0.2, -0.1)[[0, 1, 3]],
                               [[0.2, -0.1], [0.2, 0.0], [0.3, -0.1]], atol=1e-15)


# --------------------------------------------------------------------------- nothing computed, nothing earned
NOTHING = {
    "02_homography": """
        import numpy as np
        def apply_homography(H, pts):
            return np.zeros((len(pts), 2))
        def estimate_homography(src, dst):
            return np.eye(3)
        """,
    "03_intrinsic_calibration": """
        import numpy as np
        def intrinsic_constraints(H):
            return np.zeros((2, 6))
        def intrinsics_from_homographies(Hs):
            if len(Hs) < 3:
                raise ValueError("need 3 views")
            return np.eye(3)
        def extrinsics_from_homography(K, H):
            return np.eye(3), np.array([0.0, 0.0, 1.0])
        """,
}


@pytest.mark.parametrize("assignment", list(NOTHING))
def test_code_that_computes_nothing_scores_zero(tmp_path, material, assignment):
    sub = tmp_path / f"{assignment}.py"
    sub.write_text(textwrap.dedent(NOTHING[assignment]))
    res = grade_file(sub, material, assignment)
    assert res.score == 0, text(res)
    gated = [t for f in res.functions for t in f.tests if t.output == FORM_GATED]
    assert len(gated) >= 3


# --------------------------------------------------------------------------- pinned scores
#: exact scores of the mistakes corpus (total over the assignment's functions); a change in
#: the partial-credit formula (e.g. round(fraction) * weight) or in a tolerance moves them
PINNED = {
    "01_pinhole_projection__K_transposed": 0, "01_pinhole_projection__R_transposed": 0,
    "01_pinhole_projection__float32": 0, "01_pinhole_projection__modifies_input": 9,
    "01_pinhole_projection__no_division": 0, "01_pinhole_projection__skew_dropped": 4,
    "01_pinhole_projection__squeeze": 9, "01_pinhole_projection__t_subtracted": 0,
    "01_pinhole_projection__uv_swapped": 0, "02_homography__apply_H_inverted": 0,
    "02_homography__apply_H_transposed": 0, "02_homography__apply_no_division": 0,
    "02_homography__estimate_H_transposed": 10, "02_homography__estimate_bad_denormalization": 10,
    "02_homography__estimate_no_denormalization": 10, "02_homography__estimate_no_normalization": 18.4,
    "02_homography__estimate_not_scaled": 16, "03_intrinsic_calibration__K_lambda_ignored": 10,
    "03_intrinsic_calibration__K_no_raise": 18.4, "03_intrinsic_calibration__K_principal_point": 16,
    "03_intrinsic_calibration__K_skew_dropped": 16, "03_intrinsic_calibration__b_order": 0,
    "03_intrinsic_calibration__pose_board_behind": 8.4, "03_intrinsic_calibration__pose_not_orthonormalized": 6.8,
    "03_intrinsic_calibration__rows_not_columns": 0, "03_intrinsic_calibration__second_as_sum": 0,
    "04_distortion_rectification__distort_pixels": 14, "04_distortion_rectification__k3_ignored": 7,
    "04_distortion_rectification__maps_float64": 17, "04_distortion_rectification__maps_swapped": 10,
    "04_distortion_rectification__maps_transposed": 10, "04_distortion_rectification__new_K_ignored": 14,
    "04_distortion_rectification__radial_in_r": 0, "04_distortion_rectification__tangential_swapped": 6,
    "04_distortion_rectification__undistort_fixed_iterations": 14.4,
    "04_distortion_rectification__undistort_fixed_point_stalls": 16.8,
    "05_extrinsic_calibration__axes_swapped": 0, "05_extrinsic_calibration__column_order": 0,
    "05_extrinsic_calibration__from_left": 0, "05_extrinsic_calibration__off_by_one": 0,
    "05_extrinsic_calibration__pixel_H_transposed": 0, "05_extrinsic_calibration__pixel_no_division": 0,
    "02_homography__estimate_denormalization_order": 10, "03_intrinsic_calibration__K_principal_point_fx": 16,
    "04_distortion_rectification__distort_pixel_offsets": 14,
    "04_distortion_rectification__maps_float64_transposed": 10, "05_extrinsic_calibration__from_far_row": 0,
    "05_extrinsic_calibration__camera_H_not_inverted": 0, "05_extrinsic_calibration__camera_height_sign": 0,
    "05_extrinsic_calibration__camera_pitch_radians": 0, "05_extrinsic_calibration__camera_pitch_sign": 0,
    "02_homography__apply_divides_H_in_place": 19, "05_extrinsic_calibration__camera_abs_pitch": 28.8,
}


def test_scores_of_known_partial_submissions_are_pinned(mistake_results):
    assert {stem: res.score for stem, res in mistake_results.items()} == PINNED


#: how a failed check says what is wrong when its function has no named diagnosis
SENTENCES = ("wrong on ", "your H ", "your K ", "your pose ", "R is not a rotation", "puts the board behind",
             "should ", "no points for form yet", "raised ", "changed its input", "not defined", "not implemented")


def test_every_lost_point_comes_with_a_sentence(mistake_results):
    for stem, res in mistake_results.items():
        for f in res.functions:
            for t in f.tests:
                if t.score < t.max_score:
                    assert f.diagnosis or any(w in t.output for w in SENTENCES), (stem, t.name, t.output)
                    # numbers alone ("case 1: the answer is off by ...") are not words
                    assert not re.match(r"case \d+: the answer", t.output), (stem, t.output)


def test_the_seven_classes_of_the_issue_are_named(mistake_results):
    named = {
        "02_homography__estimate_denormalization_order": "de-normalization in the wrong order",
        "04_distortion_rectification__distort_pixels": "distortion applied in pixels",
        "04_distortion_rectification__distort_pixel_offsets": "evaluated on pixel-sized numbers",
        "03_intrinsic_calibration__K_principal_point_fx": "principal point formula slip",
        "04_distortion_rectification__maps_float64_transposed": "the maps are transposed",
        "05_extrinsic_calibration__from_far_row": "corners starting from the far row",
        "05_extrinsic_calibration__from_left": "corners starting from the left",
        "02_homography__estimate_no_normalization": "no normalization",
    }
    for stem, words in named.items():
        assert words in text(mistake_results[stem]), stem


def test_partial_credit_is_the_fraction_of_cases_times_the_weight(mistake_results):
    # the board-behind mistake is wrong on the 2 of the 4 exact poses given with a negative scale (cases 1 and 3:
    # the sign alternates, first negative, never left to the seed) of a check worth 3.2 points: 1.6 / 3.2
    res = mistake_results["03_intrinsic_calibration__pose_board_behind"]
    f = next(f for f in res.functions if f.name == "extrinsics_from_homography")
    t = next(t for t in f.tests if t.name.startswith("exact poses"))
    assert (t.score, t.max_score) == (1.6, 3.2)
    assert "wrong on 2 of 4 case(s)" in t.output and "case 1: the right answer with the opposite sign" in t.output
    assert "case 3: the right answer with the opposite sign" in t.output


# --------------------------------------------------------------------------- one rule table (issue 28, item 2)
RULES = Path(__file__).parent / "grading_corpus_rules"


@pytest.fixture(scope="module")
def rules_results(material):
    items, skipped = discover(RULES)
    assert not skipped
    return {Path(r.submission).stem: r for r in grade_all(items, material, jobs=2)}


def _self_checks(path: Path) -> dict:
    """The public self-check's report of every exercise function ``path`` defines (run in this process)."""
    import contextlib
    import io

    import dtscal_lib.teaching.selfcheck as sc

    ns = runpy.run_path(str(path), run_name=f"student_{path.stem}")
    assignment = next(a for a in ASSIGNMENTS if path.name.startswith(a))
    out = {}
    for func in ASSIGNMENTS[assignment]:
        if func in ns:
            with contextlib.redirect_stdout(io.StringIO()):
                out[func] = getattr(sc, f"check_{func}")(ns[func])
    return out


def _agree(res, reports) -> list[str]:
    """The functions on which the self-check and the grader disagree (self-check passes <=> full marks)."""
    return [f"{f.name}: self-check {reports[f.name].status}, grader {f.score:g} / {f.max_score:g}\n"
            f"{reports[f.name].text()}\n{text(res)}"
            for f in res.functions if f.name in reports and reports[f.name].passed != (f.score == f.max_score)]


@pytest.mark.parametrize("corpus", ["grading_corpus", "grading_corpus_correct", "grading_corpus_rules"])
def test_self_check_passes_exactly_when_the_grader_gives_full_marks(corpus, mistake_results, correct_results,
                                                                    rules_results):
    results = {"grading_corpus": mistake_results, "grading_corpus_rules": rules_results,
               "grading_corpus_correct": {Path(k).stem: v for k, v in correct_results.items()}}[corpus]
    paths = sorted((Path(__file__).parent / corpus).glob("*.py"))
    assert len(paths) >= 10
    bad = [d for p in paths for d in _agree(results[p.stem], _self_checks(p))]
    assert not bad, "\n\n".join(bad[:3])


@pytest.mark.parametrize("path", sorted(RULES.glob("*.py")), ids=lambda p: p.stem)
def test_a_broken_rule_charges_its_function_once_with_the_same_words(path, rules_results):
    src = path.read_text()
    charged = {f.strip() for f in re.search(r"# charged: (.*)", src).group(1).split(",")}
    expect = re.search(r"# expect: (.*)", src).group(1).strip()
    res, reports = rules_results[path.stem], _self_checks(path)
    lost = {f.name for f in res.functions if f.score < f.max_score and f.status != "missing"}
    assert lost == charged, text(res)  # the function that breaks the rule, and no other (one call, one charge)
    assert {f for f, r in reports.items() if not r.passed} == charged
    assert expect in text(res)
    for f in res.functions:
        if f.status in ("academic honesty", "not allowed"):  # refused: the self-check says what the grader says
            assert f.tests[0].output in reports[f.name].text(), reports[f.name].text()


def _refs_submission(tmp_path: Path, assignment: str, defs: dict) -> Path:
    """A submission made of tests/selfcheck_refs.py's functions (their source), each exercise a thin wrapper."""
    import inspect

    import selfcheck_refs as refs

    used = sorted({name for fn in defs.values() for name in fn})
    src = ["import math", "", "import cv2", "import numpy as np", ""]
    src += [inspect.getsource(getattr(refs, name)) for name in used]
    for func, (name, *_rest) in defs.items():
        src.append(f"def {func}(*args):\n    return {name}(*args)\n")
    path = tmp_path / f"{assignment}__{'_'.join(n for n, *_ in defs.values())}.py"
    path.write_text("\n\n".join(src), encoding="utf-8")
    return path


def test_self_check_agrees_with_the_grader_on_the_self_check_references(tmp_path, material):
    subs = [_refs_submission(tmp_path, "03_intrinsic_calibration", {
                "intrinsic_constraints": ("ref_constraints",),
                "intrinsics_from_homographies": ("ref_intrinsics", "ref_constraints")}),
            _refs_submission(tmp_path, "04_distortion_rectification", {
                "distort_normalized": ("np_distort",), "undistort_normalized": ("np_undistort", "np_distort"),
                "rectification_maps": ("np_maps", "np_distort")})]
    subs += [_refs_submission(tmp_path, "05_extrinsic_calibration", {"pixel_to_ground": (name, "ref_p2g")})
             for name in ("ref_p2g", "p2g_transposed", "p2g_no_divide", "cv2_p2g")]
    results = {p.stem: grade_file(p, material, p.stem.split("__")[0]) for p in subs}
    bad = [d for p in subs for d in _agree(results[p.stem], _self_checks(p))]
    assert not bad, "\n\n".join(bad[:3])
    full = {p.stem.split("__")[1]: [f.score == f.max_score for f in results[p.stem].functions
                                    if f.status != "missing"] for p in subs}
    assert full["ref_p2g"] == [True] and full["cv2_p2g"] == [False]
    assert all(full["np_distort_np_undistort_np_maps"])
