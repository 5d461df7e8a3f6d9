"""One rule table per notebook (issue 28, items 2 and 8): what the notebook says, the self-check enforces and the
grader holds. In-process and cheap; the corpora graded through the sandbox live in test_grading_fairness.py
(self-check passes <=> full marks, on every corpus)."""

from __future__ import annotations

import runpy
import shutil

import nbformat
import numpy as np
import pytest

from dtscal_lib import exercise_rules as rules
from dtscal_lib import mistakes
from dtscal_lib.grading import checks, harness
from dtscal_lib.grading.checks import build_check, inputs_and_truth
from dtscal_lib.grading.material import ASSIGNMENTS, Material, MaterialError
from dtscal_lib.grading.sandbox import Call, CheckRun
from dtscal_lib.grading.specs import SpecError, typed
from nbtools import NOTEBOOKS, ROOT, SOLUTIONS

CASES = runpy.run_path(str(ROOT / "grading" / "cases.py"))["CHECKS"]


# --------------------------------------------------------------------------- the table
def test_one_table_per_notebook_and_the_allowed_modules_constant():
    assert {nb: r.functions for nb, r in rules.NOTEBOOKS.items()} == ASSIGNMENTS
    assert set(rules.RETURNS) == {f for fs in ASSIGNMENTS.values() for f in fs}
    for nb, mods in rules.ALLOWED_MODULES.items():  # what the sandbox manifest reads (issue 28, item 1)
        assert {"numpy", "math"} <= set(mods) and "scipy" not in mods and "cv2" not in mods, nb
    assert rules.module_allowed("functools", "02_homography") and not rules.module_allowed("scipy", "02_homography")


@pytest.mark.parametrize("nb", list(ASSIGNMENTS))
def test_the_notebook_states_its_rule_table(nb):
    for folder in (SOLUTIONS, NOTEBOOKS):  # the solution and the student's copy generated from it
        cells = nbformat.read(str(folder / f"{nb}.ipynb"), as_version=4).cells
        assert any(c.cell_type == "markdown" and c.source == rules.rules_markdown(nb) for c in cells), folder
    text = rules.rules_markdown(nb)
    for func, routines in rules.NOTEBOOKS[nb].shortcuts:
        assert all(f"`cv2.{r}`" in text for r in routines) and f"`{func}`" in text


def test_notebook_04_says_initUndistortRectifyMap_is_forbidden():
    cells = nbformat.read(str(SOLUTIONS / "04_distortion_rectification.ipynb"), as_version=4).cells
    exercise = next(c.source for c in cells if "Write `rectification_maps(" in c.source)
    assert "cv2.initUndistortRectifyMap" in exercise and "**forbidden**" in exercise


@pytest.mark.parametrize("value", [[[1.0, 2.0], [3.0, 4.0]], [0.1, 18.0], (0.1, 18.0), np.ma.array(np.eye(3)),
                                   (np.zeros((2, 2)), [1.0, 2.0]), [np.zeros(3), np.ones(3)], np.zeros((2, 2)),
                                   (np.zeros((2, 2), np.float32), np.zeros((2, 2), np.float32)), 3.0])
def test_the_sandbox_describes_an_answer_as_the_rule_table_does(value):
    """The grader's words on a returned value come from the sandbox's note; the self-check computes the same."""
    desc = harness._encode(value, harness._Blobs(), np)
    assert desc.get("note", "") == rules.answer_note(value)
    if isinstance(value, list) and not any(isinstance(v, (np.ndarray, tuple)) for v in value):
        assert desc["kind"] == "array"  # a nested list of numbers is ONE answer (not "a tuple of three arrays")


def test_a_nested_list_is_refused_with_the_same_words_for_every_function():
    words = {f: rules.return_type_problem(f, [[0.0, 1.0], [2.0, 3.0]]) for f in rules.RETURNS}
    assert all("got a list: return numpy arrays" in w for w in words.values())
    assert rules.return_type_problem("rectification_maps", [np.zeros((2, 3), np.float32)] * 2).startswith(
        "should return a tuple of 2 numpy arrays")
    assert rules.return_type_problem("camera_height_pitch", np.array([0.1, 18.0])) == ""


# --------------------------------------------------------------------------- forbidden shortcuts, imports
def _student(src: str, name: str):
    ns: dict = {"__name__": "__main__"}
    exec(compile(src, "<cell>", "exec"), ns)  # noqa: S102 - a student's notebook cell
    return ns[name]


def test_a_forbidden_call_is_found_through_aliases_and_own_helpers_but_not_through_another_exercise(tmp_path):
    path = tmp_path / "cell.py"  # inspect reads a function's source from its file, as IPython's cells
    path.write_text(
        "import cv2 as c\nimport numpy as np\nfrom scipy import linalg as la\n\n"
        "def _helper(H, p):\n    return c.perspectiveTransform(p.reshape(-1, 1, 2), H).reshape(-1, 2)\n\n"
        "def apply_homography(H, p):\n    return _helper(H, p)\n\n"
        "def estimate_homography(src, dst):\n    apply_homography(np.eye(3), src)\n    return la.svd(src)\n")
    ns = runpy.run_path(str(path), run_name="__main__")
    honesty, modules = rules.live_charges("apply_homography", ns["apply_homography"])
    assert honesty == rules.honesty_reason("apply_homography", ["cv2.perspectiveTransform (through _helper)"])
    honesty, modules = rules.live_charges("estimate_homography", ns["estimate_homography"])
    assert honesty == ""  # one call, one charge: apply_homography is charged, not its caller
    assert "uses scipy.linalg.svd" in modules


def test_the_grader_and_the_self_check_read_the_same_charges(tmp_path):
    from dtscal_lib.grading.loader import load_submission

    path = tmp_path / "02_homography.py"
    path.write_text("import cv2\nimport numpy as np\n\ndef apply_homography(H, p):\n"
                    "    return cv2.perspectiveTransform(p, H)\n\ndef estimate_homography(s, d):\n"
                    "    return apply_homography(np.eye(3), s)\n")
    sub = load_submission(path)
    found = rules.charges(sub.functions, sub.aliases, "02_homography", ASSIGNMENTS["02_homography"])
    ns = runpy.run_path(str(path), run_name="__main__")
    for func in ASSIGNMENTS["02_homography"]:
        want = rules.honesty_reason(func, found.honesty[func]) if func in found.honesty else ""
        assert rules.live_charges(func, ns[func])[0] == want
    assert list(found.honesty) == ["apply_homography"]


# --------------------------------------------------------------------------- the precision contract
def test_float32_inside_fails_the_precision_contract_and_float64_keeps_it():
    for func in mistakes.FUNCTIONS:
        if func in mistakes.NO_PRECISION:
            continue
        args = mistakes.probe_args(func)
        right = mistakes.right_answers(func, args)
        exact = [r for r in right if r is not None]
        assert exact, func
        outs = [r if r is not None else None for r in right]
        assert mistakes.precision_problem(func, args, outs) == "", func
        f32 = [tuple(np.asarray(x, np.float32).astype(float) for x in r) if isinstance(r, tuple) else
               np.asarray(r, np.float32).astype(float) * (1 + 3e-7) if r is not None else None for r in right]
        assert "float32 arithmetic" in mistakes.precision_problem(func, args, f32), func


def test_the_float32_hint_only_at_float32_scale():
    want = np.array([[120.0, 250.0], [33.0, 410.0]])
    assert "float32" in checks.explain(want * (1 + 4e-7), want)
    assert "float32" not in checks.explain(want + 0.4, want)
    # a right first output does not make a wrong second one "float32"
    pair = (np.array([1.0, 2.0]), np.array([0.1, 18.0]))
    assert "float32" not in checks.explain((pair[0] * (1 + 1e-15), pair[1] + [0.0, 0.4]), pair)
    assert not rules.float32_sized(1e-15) and not rules.float32_sized(0.4 / 18) and rules.float32_sized(2e-7)


# --------------------------------------------------------------------------- typed hidden cases
@pytest.mark.parametrize("bad, key", [(dict(camer="4k"), "'camer'"), (dict(atl=1e-6), "'atl'"),
                                      (dict(camera="5k"), "camera='5k'"), (dict(judge="closest"), "'closest'")])
def test_an_unknown_key_of_a_hidden_case_is_an_error_that_names_it(bad, key):
    spec = dict(name="noise-free pixels", weight=3, seed=1, views=1, n=3) | bad
    with pytest.raises(SpecError, match=key):
        typed("project_points", spec)


def test_the_material_refuses_a_misspelt_key_before_grading(tmp_path):
    kit = tmp_path / "kit"
    shutil.copytree(ROOT / "grading", kit / "grading")
    (kit / "solutions").mkdir()
    cases = kit / "grading" / "cases.py"
    cases.write_text(cases.read_text().replace("camera=\"4k\", atol=1e-5", "camer=\"4k\", atol=1e-5", 1))
    with pytest.raises(MaterialError, match="unknown key.*'camer'"):
        Material.load(kit)


def test_every_check_of_the_material_is_typed():
    kinds = {spec.get("judge", "close") for specs in CASES.values() for spec in specs}
    assert {"close", "unchanged", "dtype", "precision"} <= kinds
    for func, specs in CASES.items():
        for spec in specs:
            typed(func, spec)


def _homographies(func, args):
    """The homographies among one call's arguments."""
    if func == "intrinsics_from_homographies":
        return list(args[0])
    return [args[1]] if func == "extrinsics_from_homography" else [args[0]]


H_FUNCS = ("apply_homography", "pixel_to_ground", "intrinsic_constraints", "intrinsics_from_homographies",
           "extrinsics_from_homography", "camera_height_pitch")


@pytest.mark.parametrize("func", H_FUNCS)
def test_inputs_not_modified_is_checked_on_homographies_with_H22_not_1(func):
    specs = [s for s in CASES[func] if s.get("judge") == "unchanged"]
    assert specs, func
    for spec in specs:
        args_list, _ = inputs_and_truth(func, spec, np.random.default_rng(spec["seed"]))
        Hs = [H for args in args_list for H in _homographies(func, args)]
        assert Hs and all(abs(H[2, 2] - 1.0) > 0.5 for H in Hs), func


def _judge_in_process(func, spec, student, reference):
    built = build_check(func, spec, reference)
    calls = []
    for _, args in built.calls:
        copies = tuple([x.copy() for x in a] if isinstance(a, list) else a.copy() if isinstance(a, np.ndarray)
                       else a for a in args)
        value = student(*copies)
        calls.append(Call(ok=True, value=value, args_after=[np.asarray(a) if isinstance(a, (list, np.ndarray))
                                                             else None for a in copies]))
    return built.judge(built, CheckRun(calls=calls))


def _apply(H, pts):
    return mistakes._homog(H, pts)


def test_dividing_H_in_place_is_caught():
    def divides_in_place(H, pts):
        H /= H[2, 2]
        return _apply(H, pts)

    spec = next(s for s in CASES["apply_homography"] if s.get("judge") == "unchanged")
    frac, why = _judge_in_process("apply_homography", spec, divides_in_place, _apply)
    assert frac == 0 and "changed its input argument 1" in why

    def zhang_in_place(Hs):
        for H in Hs:
            H /= H[2, 2]
        return np.eye(3)

    spec = next(s for s in CASES["intrinsics_from_homographies"] if s.get("judge") == "unchanged")
    K = checks.CAMERAS["skewed"]
    frac, why = _judge_in_process("intrinsics_from_homographies", spec, zhang_in_place, lambda Hs: K)
    assert frac == 0 and "changed its input argument 1" in why


@pytest.mark.parametrize("func", sorted({f for f, specs in CASES.items() for s in specs if s.get("random_scale")}))
def test_random_scale_and_sign_checks_hold_both_signs_whatever_the_seed(func):
    """Case i is multiplied by -1 for even i, +1 for odd i: forced, never left to the seed."""
    for spec in [s for s in CASES[func] if s.get("random_scale")]:
        for seed in (spec["seed"], 1, 2, 3):
            signed = [H for a in inputs_and_truth(func, spec, np.random.default_rng(seed))[0]
                      for H in _homographies(func, a)]
            plain = [H for a in inputs_and_truth(func, dict(spec, random_scale=False),
                                                 np.random.default_rng(seed))[0] for H in _homographies(func, a)]
            assert len(signed) >= 2, func
            # the first case is drawn from the same pose either way: its sign is flipped
            assert np.sign(signed[0][2, 2]) == -np.sign(plain[0][2, 2]), (func, seed)
            if func != "camera_height_pitch":  # board homographies have H[2, 2] = 1 before the scale
                assert [np.sign(H[2, 2]) for H in signed] == [(-1.0) ** (i + 1) for i in range(len(signed))]


def test_a_camera_pitched_up_is_a_hidden_case_and_abs_on_the_pitch_fails_it():
    spec = next(s for s in CASES["camera_height_pitch"] if s.get("pitch") and s["pitch"][1] < 0)
    right = mistakes.MISTAKES["camera_height_pitch"][0]
    frac, _ = _judge_in_process("camera_height_pitch", spec, lambda H, K: np.abs(right(H, K)), right)
    assert frac == 0
    assert _judge_in_process("camera_height_pitch", spec, right, right)[0] == 1


# --------------------------------------------------------------------------- camera_height_pitch's mistakes
def _camera_height_pitch(*, k_inv=True, invert_H=True, k_T=False, lam_col=0, t_col=2, unit=1.0, height="C_z",
                         pitch="below", swap=False, absolute=False):
    """A student's camera_height_pitch, written as the notebook's hint says, with one slip switched on."""
    def f(H, K):
        Hi = np.linalg.inv(H) if invert_H else np.asarray(H, float)
        Kx = np.asarray(K, float).T if k_T else np.asarray(K, float)
        M = np.linalg.inv(Kx) @ Hi if k_inv else Hi
        lam = 1.0 / np.linalg.norm(M[:, lam_col])
        if lam * (0.3 * M[2, 0] + M[2, 2]) < 0:
            lam = -lam
        r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, t_col]
        U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
        R = U @ Wt
        C = -R.T @ t
        h = {"C_z": C[2], "C_x": C[0], "t_z": t[2], "-Rt": (-R @ t)[2]}[height] * unit
        p = np.degrees(np.arcsin(-R[2, 2]))
        p = {"below": p, "vertical": np.degrees(np.arccos(-R[2, 2]))}[pitch]
        p = abs(p) if absolute else p
        return np.array([p, h] if swap else [h, p])
    return f


SLIPS = {
    "K_inverse_forgotten": dict(k_inv=False), "H_not_inverted": dict(invert_H=False), "K_transposed": dict(k_T=True),
    "t_wrong_column": dict(t_col=1), "lambda_from_t": dict(lam_col=2), "height_in_mm": dict(unit=1000.0),
    "height_in_cm": dict(unit=100.0), "height_is_t_z": dict(height="t_z"), "height_is_C_x": dict(height="C_x"),
    "C_is_minus_R_t": dict(height="-Rt"), "pitch_from_vertical": dict(pitch="vertical"),
    "outputs_swapped": dict(swap=True), "abs_pitch": dict(absolute=True),
}


@pytest.mark.parametrize("key", list(SLIPS))
def test_each_camera_height_pitch_mistake_of_the_issue_is_named(key):
    assert mistakes.diagnose_function("camera_height_pitch", _camera_height_pitch()) is None
    found = mistakes.diagnose_function("camera_height_pitch", _camera_height_pitch(**SLIPS[key]))
    assert found is not None and found.key == key, found
    assert "eq." in found.equation


def test_the_self_check_fails_each_camera_height_pitch_mistake():
    import contextlib
    import io

    from dtscal_lib.teaching.selfcheck import check_camera_height_pitch

    with contextlib.redirect_stdout(io.StringIO()):
        assert check_camera_height_pitch(_camera_height_pitch()).passed
        failed = [k for k, slip in SLIPS.items() if not check_camera_height_pitch(_camera_height_pitch(**slip)).passed]
    assert failed == list(SLIPS)


def test_a_local_variable_named_like_a_notebook_import_is_the_students_own():
    """The hub journey's student wrote ``cam = X @ R.T + t`` in project_points beside the notebook's ``from dtscal_lib
    import camera as cam``: the self-check refused it as a call of the kit's camera (0/1). A name the function binds
    is its own; a name bound to a module or routine (``c = cv2``) is an alias of it, and still charged."""
    import ast

    from dtscal_lib.exercise_rules import charges

    src = (
        "def project_points(K, R, t, X):\n"
        "    cam = X @ R.T + t\n"
        "    uvw = cam @ K.T\n"
        "    return (uvw[:, :2] / uvw[:, 2:3]).T.T\n"
        "def estimate_homography(src, dst):\n"
        "    c = cv2\n"
        "    return c.findHomography(src, dst)[0]\n"
        "def apply_homography(H, pts, cam=None):\n"
        "    return cam.T\n"
    )
    fns = {n.name: n for n in ast.parse(src).body}
    aliases = {"cam": "dtscal_lib.camera", "cv2": "cv2", "np": "numpy"}
    got = charges(fns, aliases)
    assert "project_points" not in got.honesty and "apply_homography" not in got.honesty, got.honesty
    assert got.honesty.get("estimate_homography") == ["cv2.findHomography"], got.honesty
