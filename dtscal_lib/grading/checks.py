"""What is checked, per exercise function: inputs, reference answers, and the judges.

The *parameters* of every check (seeds, sizes, noise levels, offsets, weights) are not here:
they are the instructor's hidden grading material (``grading/cases.py`` of the kit, see
:mod:`dtscal_lib.grading.material`). This module turns one check description into the
calls to make and the judge of their answers.

References are computed in the grader process, never in the student's: the solution
notebook's function (loaded like a student's) on a copy of the inputs, and an independent
reference (ground truth by construction, or OpenCV), which must agree with the solution
before anything is judged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import cv2
import numpy as np

from .. import duckietown as dt
from ..boards import DUCKIETOWN_BOARD
from ..camera import intrinsic_matrix, new_camera_matrix
from ..camera import undistort_normalized as newton
from ..errors import DtscalError
from ..exercise_rules import PRECISION_RTOL, float32_sized, raises_problem, relative_error, return_type_problem
from ..mistakes import precision_problem, probe_args, robot_ground_homography
from ..poses import board_homography, points_on_rays, random_board_pose
from .metrics import K_max_px, apply_homography, pose_errors, shape_key, truth_rms_px
from .sandbox import Call, CheckRun
from .specs import typed

CAMERAS = {
    "duckie": intrinsic_matrix(307.7, 315.0, 329.7, 244.5),
    "skewed": intrinsic_matrix(312.0, 318.0, 327.0, 241.0, skew=6.0),
    "4k": intrinsic_matrix(2950.0, 2940.0, 1921.0, 1083.0, skew=2.0),
}
LENSES = {
    "duckiebot": dt.default_dist(),
    "tangential": np.array([-0.12, 0.03, 0.02, -0.015, 0.0]),
    "radial_k3": np.array([-0.28, 0.07, 0.0, 0.0, -0.008]),
    "none": np.zeros(5),
}


class MaterialError(DtscalError):
    """The grading material or the reference solution is wrong (an instructor's problem)."""


@dataclass
class Built:
    """One check ready to run: the calls to make, the expected answers, the judge."""

    func: str
    name: str
    weight: float
    calls: list[tuple] = field(default_factory=list)
    refs: list = field(default_factory=list)
    judge: Callable = None
    extra: dict = field(default_factory=dict)
    #: a check of form (dtype, shape, inputs untouched, raising, H[2, 2] = 1), see FORM_JUDGES
    form: bool = False


# --------------------------------------------------------------------------- inputs
def _pose(rng, distance=(0.3, 0.9), max_deg=40.0):
    return random_board_pose(rng, DUCKIETOWN_BOARD, tilt_deg=(5.0, max_deg), distance=distance, spread=(0.2, 0.15))


def _sign(rng, i: int) -> float:
    """The sign of case ``i`` of a check "at random scale and sign": forced, never left to the seed. The first
    case is negative and the signs alternate, so every such check holds both signs from two cases on. (The
    random draw is kept so the other inputs stay those of the seed.)"""
    rng.choice([-1.0, 1.0])
    return -1.0 if i % 2 == 0 else 1.0


def _rescaled(H, p: dict):
    """``H`` scaled so that H[2, 2] = ``p["h33"]`` (a homography is defined up to scale; an input with
    H[2, 2] != 1 shows code that divides it in place, ``H /= H[2, 2]``)."""
    return H * (float(p["h33"]) / H[2, 2]) if p.get("h33") is not None else H


def _img_span(K):
    return 2 * K[0, 2], 2 * K[1, 2]


_apply = apply_homography


def inputs_and_truth(func: str, p: dict, rng) -> tuple[list[tuple], list]:
    """The argument tuples of one check and, where known, the true answers (else None).

    With noise (``sigma``), the truth is what the case was drawn from (the true H, K or
    pose), not what the noisy inputs determine exactly."""
    n, views = int(p.get("n", 20)), int(p.get("views", 1))
    if func == "project_points":
        K = CAMERAS[p.get("camera", "skewed")]
        w, h = _img_span(K)
        args, truth = [], []
        for _ in range(views):
            R, t = _pose(rng, distance=tuple(p.get("distance", (0.3, 0.9))))
            uv = np.column_stack([rng.uniform(0.03 * w, 0.97 * w, n), rng.uniform(0.03 * h, 0.97 * h, n)])
            args.append((K.copy(), R, t, points_on_rays(K, R, t, uv, rng.uniform(*p.get("depth", (0.3, 2.0)), n))))
            truth.append(uv)
        return args, truth
    if func in ("apply_homography", "pixel_to_ground"):
        args, truth = [], []
        for _ in range(views):
            R, t = _pose(rng)
            H = board_homography(CAMERAS[p.get("camera", "duckie")], R, t) * float(p.get("scale", 1.0))
            H = H * _sign(rng, len(args)) * rng.uniform(0.5, 50.0) if p.get("random_scale") else H
            pts = np.column_stack([rng.uniform(-0.1, 0.3, n), rng.uniform(-0.1, 0.25, n)])
            if func == "pixel_to_ground":
                H, pts = np.linalg.inv(H), _apply(H, pts)
            args.append((_rescaled(H, p), pts))
            truth.append(_apply(H, pts))
        return args, truth
    if func == "estimate_homography":
        args, truth = [], []
        off, span, sigma = float(p.get("offset", 0.0)), float(p.get("span", 1.0)), float(p.get("sigma", 0.0))
        for _ in range(views):
            R, t = _pose(rng)
            src = np.column_stack([rng.uniform(0, 640, n), rng.uniform(0, 480, n)]) * span + off
            A = np.array([[0.25 / (640 * span), 0, -off * 0.25 / (640 * span)],
                          [0, 0.2 / (480 * span), -off * 0.2 / (480 * span)], [0, 0, 1.0]])
            H = board_homography(CAMERAS[p.get("camera", "duckie")], R, t) @ A
            H /= H[2, 2]
            dst = _apply(H, src) + rng.normal(0.0, sigma, size=(n, 2))
            args.append((src, dst))
            truth.append(H)
        return args, truth
    if func in ("intrinsic_constraints", "intrinsics_from_homographies", "extrinsics_from_homography"):
        K = CAMERAS[p.get("camera", "skewed")]
        sigma = float(p.get("sigma", 0.0))
        Hs, poses = [], []
        for _ in range(max(views, 1)):
            R, t = _pose(rng, distance=(0.35, 0.7), max_deg=45.0)
            if sigma:
                obj = DUCKIETOWN_BOARD.object_points()[:, :2]
                img = _apply(board_homography(K, R, t), obj) + rng.normal(0.0, sigma, size=(len(obj), 2))
                H = cv2.findHomography(obj, img, 0)[0]
            else:
                H = board_homography(K, R, t)
            if p.get("random_scale"):
                H = H * _sign(rng, len(Hs)) * rng.uniform(0.01, 100.0)
            Hs.append(_rescaled(H, p))
            poses.append((R, t))
        if func == "intrinsic_constraints":
            Hs = Hs if not p.get("random_H") else [rng.normal(size=(3, 3)) * [[300.0], [300.0], [1.0]]
                                                   for _ in Hs]
            return [(H,) for H in Hs], [None] * len(Hs)
        if func == "intrinsics_from_homographies":
            return [(Hs,)], [K]
        return [(K.copy(), H) for H in Hs], poses
    if func in ("distort_normalized", "undistort_normalized"):
        d = np.array(p["dist"], float) if "dist" in p else LENSES[p.get("lens", "duckiebot")]
        if p.get("region") == "image":  # the distorted image's pixels, corners included
            K = dt.default_K()
            us, vs = np.meshgrid(np.r_[0:640:16, 639], np.r_[0:480:16, 479])
            xy_d = (np.column_stack([us.ravel(), vs.ravel(), np.ones(us.size)]) @ np.linalg.inv(K).T)[:, :2]
            xy = newton(xy_d, d)
        else:
            xy = rng.uniform(-float(p.get("radius", 0.8)), float(p.get("radius", 0.8)), size=(n, 2))
        xy_d = _cv_distort(xy, d)
        if func == "distort_normalized":
            return [(xy, d.copy())], [xy_d]
        return [(xy_d, d.copy())], [xy]
    if func == "rectification_maps":
        K = intrinsic_matrix(*p["K"]) if "K" in p else dt.default_K()
        d = LENSES[p.get("lens", "duckiebot")]
        size = tuple(p.get("size", dt.IMAGE_SIZE))
        new_K = K.copy() if p.get("alpha") is None else new_camera_matrix(K, d, size, float(p["alpha"]))
        maps = cv2.initUndistortRectifyMap(K, d, None, new_K, size, cv2.CV_32FC1)
        return [(K, d.copy(), new_K, size)], [maps]
    if func == "board_ground_points":
        boards = p.get("boards", [(7, 5, 0.031, 0.191, -0.093)])
        truth = []
        for cols, rows, sq, x0, y0 in boards:
            k = np.arange(cols * rows)
            truth.append(np.column_stack([x0 + (k // cols) * sq, y0 + (k % cols) * sq]))
        return [tuple(b) for b in boards], truth
    if func == "camera_height_pitch":  # robot cameras placed by hand: the height and pitch are the truth
        K = dt.default_P()[:, :3] if p.get("camera", "rectified") == "rectified" else CAMERAS[p["camera"]]
        args, truth = [], []
        for _ in range(views):
            height, pitch = rng.uniform(0.05, 0.3), rng.uniform(*p.get("pitch", (5.0, 50.0)))
            H = robot_ground_homography(K, height, pitch, yaw_deg=rng.uniform(-4.0, 4.0), x=rng.uniform(0.0, 0.1))
            if p.get("random_scale"):
                H = H * _sign(rng, len(args)) * rng.uniform(0.01, 100.0)
            args.append((_rescaled(H, p), K.copy()))
            truth.append(np.array([height, pitch]))
        return args, truth
    raise MaterialError(f"no exercise function named {func}")


def _cv_distort(xy, d):
    X = np.column_stack([xy, np.ones(len(xy))])
    return cv2.projectPoints(X, np.zeros(3), np.zeros(3), np.eye(3), np.asarray(d, float))[0].reshape(-1, 2)


# --------------------------------------------------------------------------- judging helpers
def num(x) -> str:
    """A number as plain text (never ``np.float64(...)``)."""
    return f"{float(x):.6g}"


def _arrays(value) -> list | None:
    parts = list(value) if isinstance(value, tuple) else [value]
    if not parts or any(not isinstance(a, np.ndarray) for a in parts):
        return None
    return parts


def _describe_value(value) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}, dtype {value.dtype}"
    if isinstance(value, tuple):
        return "a tuple (" + ", ".join(_describe_value(v) for v in value) + ")"
    return repr(value) if value is None else f"{value!r}"


def _compare(got, want, atol: float, rtol: float, what: str) -> str:
    """'' if ``got`` matches ``want``; otherwise why not."""
    want_parts = list(want) if isinstance(want, tuple) else [want]
    got_parts = _arrays(got)
    if got_parts is None or len(got_parts) != len(want_parts):
        return f"{what}: expected {_describe_value(tuple(want) if isinstance(want, tuple) else want)}, got " \
               f"{_describe_value(got)}"
    for i, (g, w) in enumerate(zip(got_parts, want_parts)):
        w = np.asarray(w)
        label = what if len(want_parts) == 1 else f"{what} (item {i})"
        if g.shape != w.shape:
            return f"{label} should have shape {w.shape}, got {g.shape}"
        g64 = g.astype(np.float64)
        if not np.all(np.isfinite(g64)):
            return f"{label} contains NaN or infinite values"
        err = np.abs(g64 - w)
        tol = atol + rtol * float(np.abs(w).max(initial=0.0))
        if not float(err.max(initial=0.0)) <= tol:
            idx = np.unravel_index(int(np.argmax(err)), err.shape) if err.ndim else ()
            return (f"{label} is off by up to {num(err.max())} (allowed {num(tol)}); worst at index "
                    f"{tuple(int(k) for k in idx)}: got {num(g64[idx])}, expected {num(w[idx])}")
    return ""


# --------------------------------------------------------------------------- judges
# Each judge gets (built, run) and returns (fraction of the check's points in [0, 1], message).
def _calls_or_failure(built: Built, run: CheckRun):
    if run.failure:
        return None, run.failure
    if any(c.not_implemented for c in run.calls):
        return None, "not implemented (the function still raises NotImplementedError)"
    if len(run.calls) < len(built.calls):
        return None, "the check did not finish"
    return run.calls, ""


def explain(got, want, func: str = "") -> str:
    """In words, how a wrong answer differs from the right one (or '' when no pattern shows)."""
    gp, wp = _arrays(got), (list(want) if isinstance(want, tuple) else [want])
    if gp is None or len(gp) != len(wp):
        return ""
    if func == "rectification_maps" and all(g.shape == np.shape(w) for g, w in zip(gp, wp)):
        big = max(float(np.nanmax(np.abs(g.astype(float)), initial=0.0)) for g in gp)
        span = max(np.shape(wp[0]))
        if big > 1e3 * span:  # the maps' only polynomial is the lens model
            return (f"map values up to {num(big)} for a {span}-pixel-wide image: the lens polynomial was evaluated "
                    "on pixel-sized numbers; distortion applies to normalized coordinates (new_K^-1 first, then "
                    "distort, then K)")
    if len(wp) == 2 and all(g.shape == np.shape(w) for g, w in zip(gp, wp)) and all(
            np.allclose(g.astype(float), np.asarray(w), rtol=1e-6, atol=1e-6) for g, w in zip(gp, wp[::-1])):
        return "the two returned arrays are swapped"
    for g, w in zip(gp, wp):
        w, dtype = np.asarray(w, float), str(g.dtype)
        if g.shape != w.shape:
            if g.shape == w.shape[::-1] and len(w.shape) == 2:
                return f"the array is transposed: shape {w.shape} expected, {g.shape} returned"
            if g.size == w.size:
                return f"the right number of values in the wrong shape ({g.shape} instead of {w.shape}: a squeeze, " \
                       "a flatten or a missing reshape?)"
            return f"shape {g.shape} instead of {w.shape}"
        g = g.astype(float)
        if not np.all(np.isfinite(g)):
            return "NaN or infinite values: a division by zero or a square root of a negative number?"
        scale = float(np.abs(w).max(initial=0.0)) or 1.0
        err = float(np.abs(g - w).max(initial=0.0)) / scale
        if err <= PRECISION_RTOL:
            continue
        whole = relative_error(gp, wp)  # the float32 hint only when the whole answer is off by float32's scale
        if whole is not None and float32_sized(whole):
            if dtype == "float32" and np.shape(w) and str(np.asarray(w).dtype) != "float32":
                return ("a float32 answer, right to about 7 significant digits only: compute and return float64 "
                        "(no .astype(float32) anywhere)")
            return (f"right to about {max(1, int(-np.log10(whole)))} significant digits only: float32 arithmetic, "
                    "a rounded constant or a loose iteration tolerance somewhere; compute in float64 to ~1e-12")
        if np.allclose(g, -w, rtol=1e-6, atol=1e-9 * scale):
            return "the right answer with the opposite sign"
        k = float(g.ravel() @ w.ravel()) / max(float(w.ravel() @ w.ravel()), 1e-300)
        if abs(k) > 1e-12 and abs(k - 1) > 1e-6 and np.allclose(g, k * w, rtol=1e-6, atol=1e-9 * scale):
            return f"the right answer times {num(k)} (a scale factor: a missing division or normalization?)"
        if w.ndim == 2 and w.shape[1] == 2 and np.allclose(g, w[:, ::-1], rtol=1e-6, atol=1e-9 * scale):
            return "the two columns are swapped (column 0 holds the first coordinate)"
        if w.ndim == 2 and len(w) > 1 and np.allclose(np.sort(g, axis=0), np.sort(w, axis=0), rtol=1e-9,
                                                       atol=1e-12 * scale):
            return "the right values in another order (check which index runs fastest)"
        if w.ndim == 2 and w.shape[1] == 2 and len(w) > 1:
            d = g - w
            if np.allclose(d, d[0], rtol=0, atol=1e-6 * scale):
                return f"every point is shifted by the same offset ({num(d[0, 0])}, {num(d[0, 1])})"
    return ""


def judge_close(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    atol, rtol = built.extra.get("atol", 0.0), built.extra.get("rtol", 1e-9)
    bad = []
    for i, (c, ref) in enumerate(zip(calls, built.refs)):
        if not c.ok:
            bad.append(f"case {i + 1}: raised {c.error}")
            continue
        why = _compare(c.value, ref, atol, rtol, "the answer")
        if why:
            words = explain(c.value, ref, built.func)
            bad.append(f"case {i + 1}: " + (f"{words}; " if words else "") + why
                       + (f" (returned {c.note})" if c.note else ""))
    ok = len(calls) - len(bad)
    if not bad:
        return 1.0, ""
    head = f"wrong on {len(bad)} of {len(calls)} case(s) of this check ({built.extra.get('about') or built.name}). "
    return ok / len(calls), head + "; ".join(bad[:2]) + (f" (+{len(bad) - 2} more)" if len(bad) > 2 else "")


def judge_unchanged(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    for c, args in zip(calls, built.calls):
        if not c.ok:
            return 0.0, f"raised {c.error}"
        for k, a in enumerate(args[1]):
            if isinstance(a, (np.ndarray, list)):  # a list of arrays (the homographies of Zhang's method) too
                a = np.asarray(a)
                after = c.args_after[k] if c.args_after and k < len(c.args_after) else None
                if not isinstance(after, np.ndarray) or after.shape != a.shape or not np.array_equal(after, a):
                    return 0.0, f"the function changed its input argument {k + 1}; work on a copy"
    return 1.0, ""


def judge_dtype(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    for c, ref in zip(calls, built.refs):
        if not c.ok:
            return 0.0, f"raised {c.error}"
        # the rule table's return-type rule, in the self-check's words (dtscal_lib.exercise_rules)
        why = return_type_problem(built.func, c.value, c.note)
        if why:
            return 0.0, why
        for g, r in zip(_arrays(c.value), (list(ref) if isinstance(ref, tuple) else [ref])):
            if g.shape != np.shape(r):
                return 0.0, f"should return shape {np.shape(r)}, got {g.shape}"
    return 1.0, ""


def judge_precision(built: Built, run: CheckRun):
    """The precision contract (float64 inside) on the mistake catalogue's exact probes, judged by the function
    the self-check uses (:func:`dtscal_lib.mistakes.precision_problem`)."""
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    bad = next((c for c in calls if not c.ok), None)
    if bad is not None:
        return 0.0, f"raised {bad.error}"
    why = precision_problem(built.func, [a for _, a in built.calls], [c.value for c in calls])
    return (0.0, why) if why else (1.0, "")


def judge_raises(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    for c in calls:
        if c.ok:
            return 0.0, f"should raise ValueError (the input does not determine the answer), but returned " \
                        f"{_describe_value(c.value)}"
        if raises_problem(c.error):
            return 0.0, raises_problem(c.error)
    return 1.0, ""


def judge_scaled(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    for c in calls:
        if not c.ok:
            return 0.0, f"raised {c.error}"
        v = c.value
        if not isinstance(v, np.ndarray) or v.shape != (3, 3) or not np.isfinite(v[2, 2]) \
                or abs(float(v[2, 2]) - 1.0) > 1e-9:
            got = num(v[2, 2]) if isinstance(v, np.ndarray) and v.shape == (3, 3) else _describe_value(v)
            return 0.0, f"H[2, 2] should be 1, got {got}"
    return 1.0, ""


def _origin(tol: dict, stat: str, unit: str) -> str:
    """Where a noisy check's tolerance comes from, in words (stated in the feedback)."""
    return (f"correct formulations land within {num(tol['tolerance'][stat])} {unit} of the truth on cases like this "
            f"one (the largest of {len(tol['per_formulation_max'])} accepted formulations over {tol['seeds']} noise "
            f"draws is {num(tol['max'][stat])} {unit}, times {num(tol['margin'])})")


def _noisy_calls(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return None, why
    if not built.extra.get("tolerance"):
        raise MaterialError(f"{built.name}: no derived tolerance for this noisy check; run "
                            "python -m dtscal_lib.grading.tolerances --write")
    return calls, ""


def judge_truth_H(built: Built, run: CheckRun):
    """Noisy correspondences: the fit's distance from the TRUE homography (RMS over the case's
    source points, in pixels) within the tolerance derived from the accepted formulations."""
    calls, why = _noisy_calls(built, run)
    if calls is None:
        return 0.0, why
    tol = built.extra["tolerance"]
    limit = tol["tolerance"]["truth_rms_px"]
    bad = []
    for i, (c, (src, _), H_true) in enumerate(zip(calls, [a for _, a in built.calls], built.extra["truth"])):
        if not c.ok:
            bad.append(f"case {i + 1}: raised {c.error}")
            continue
        if not isinstance(c.value, np.ndarray) or c.value.shape != (3, 3) or not np.all(np.isfinite(c.value)):
            bad.append(f"case {i + 1}: expected a finite (3, 3) array, got {_describe_value(c.value)}")
            continue
        err = truth_rms_px(c.value.astype(float), H_true, src)
        if not err <= limit:
            bad.append(f"case {i + 1}: your H maps the source points {num(err)} px (RMS) away from where the true "
                       f"homography the case was drawn from maps them, allowed {num(limit)} px")
    if not bad:
        return 1.0, ""
    return (len(calls) - len(bad)) / len(calls), "; ".join(bad[:2]) + "; " + _origin(tol, "truth_rms_px", "px")


def judge_truth_K(built: Built, run: CheckRun):
    """Noisy homographies: the largest entry difference between K and the TRUE K (pixels)
    within the tolerance derived from the accepted formulations."""
    calls, why = _noisy_calls(built, run)
    if calls is None:
        return 0.0, why
    tol = built.extra["tolerance"]
    limit = tol["tolerance"]["K_max_px"]
    c, K_true = calls[0], built.extra["truth"][0]
    if not c.ok:
        return 0.0, f"raised {c.error}"
    v = c.value
    if not isinstance(v, np.ndarray) or v.shape != (3, 3) or not np.all(np.isfinite(v)):
        return 0.0, f"expected a finite (3, 3) array, got {_describe_value(v)}"
    err = K_max_px(v.astype(float), K_true)
    if err <= limit:
        return 1.0, ""
    names = ["fx", "s", "cx", "fy", "cy"]
    diffs = np.abs(v.astype(float)[[0, 0, 0, 1, 1], [0, 1, 2, 1, 2]] - K_true[[0, 0, 0, 1, 1], [0, 1, 2, 1, 2]])
    worst = names[int(np.argmax(diffs))]
    return 0.0, (f"your K is {num(err)} px from the true K the views were drawn from (worst: {worst}, "
                 f"{num(v[[0, 0, 0, 1, 1], [0, 1, 2, 1, 2]][int(np.argmax(diffs))])} instead of "
                 f"{num(K_true[[0, 0, 0, 1, 1], [0, 1, 2, 1, 2]][int(np.argmax(diffs))])}), allowed {num(limit)} px: "
                 + _origin(tol, "K_max_px", "px"))


def judge_truth_pose(built: Built, run: CheckRun):
    """Poses from noisy homographies: a proper rotation with t_z > 0, within the derived
    tolerances of the TRUE pose: rotation angle in DEGREES, translation relative to |t|."""
    calls, why = _noisy_calls(built, run)
    if calls is None:
        return 0.0, why
    tol = built.extra["tolerance"]
    max_deg, t_rel = tol["tolerance"]["deg"], tol["tolerance"]["t_rel"]
    bad = []
    for i, (c, (R_true, t_true)) in enumerate(zip(calls, built.extra["truth"])):
        parts = _arrays(c.value) if c.ok else None
        if not c.ok:
            bad.append(f"case {i + 1}: raised {c.error}")
            continue
        if parts is None or len(parts) != 2 or parts[0].shape != (3, 3) or parts[1].size != 3 \
                or not all(np.all(np.isfinite(p.astype(float))) for p in parts):
            bad.append(f"case {i + 1}: expected (R (3, 3), t (3,)), got {_describe_value(c.value)}")
            continue
        R, t = parts[0].astype(float), parts[1].astype(float).reshape(3)
        orth = float(np.abs(R.T @ R - np.eye(3)).max())
        deg, rel = pose_errors(R, t, R_true, t_true)
        if orth > 1e-6 or np.linalg.det(R) < 0:
            bad.append(f"case {i + 1}: R is not a rotation (|R^T R - I| = {num(orth)}, det = {num(np.linalg.det(R))})")
        elif t[2] <= 0:
            bad.append(f"case {i + 1}: t_z = {num(t[2])} puts the board behind the camera")
        elif deg > max_deg or rel > t_rel:
            bad.append(f"case {i + 1}: your pose is {num(deg)} deg and {num(100 * rel)} % of |t| from the true pose "
                       f"the case was drawn from, allowed {num(max_deg)} deg and {num(100 * t_rel)} %")
    if not bad:
        return 1.0, ""
    return (len(calls) - len(bad)) / len(calls), "; ".join(bad[:2]) + (
        f"; correct formulations land within {num(max_deg)} deg and {num(100 * t_rel)} % of the true pose "
        f"(the largest of {len(tol['per_formulation_max'])} accepted formulations over {tol['seeds']} noise draws, "
        f"times {num(tol['margin'])})")


JUDGES = {"precision": judge_precision, "truth_H": judge_truth_H, "truth_K": judge_truth_K,
          "truth_pose": judge_truth_pose, "close": judge_close, "unchanged": judge_unchanged, "dtype": judge_dtype,
          "raises": judge_raises, "scaled": judge_scaled}
#: judges of form, not of values: they give points only to a function whose values are right on at
#: least one case of a value check (code that computes nothing scores 0)
FORM_JUDGES = ("unchanged", "dtype", "raises", "scaled", "precision")


# --------------------------------------------------------------------------- building a check
def _copy(args):
    return tuple([np.array(x, copy=True) for x in a] if isinstance(a, list) else
                 np.array(a, copy=True) if isinstance(a, np.ndarray) else a for a in args)


def about(func: str, spec: dict) -> str:
    """What a check's case tests, in words (said when a case fails and no mistake is named)."""
    if spec.get("about"):
        return str(spec["about"])
    words = []
    if spec.get("camera") == "4k":
        words.append("pixel coordinates in the thousands: precision matters there")
    if spec.get("offset"):
        words.append(f"coordinates near {num(spec['offset'])}: an unnormalized DLT loses precision there "
                     "(activity text, eqs. (3)-(6))")
    if spec.get("random_scale"):
        words.append("homographies multiplied by a random scale and sign: the answer must not depend on them")
    if spec.get("n") == 1:
        words.append("a single point: the result keeps its (1, 2) shape")
    if spec.get("depth"):
        words.append("points far away: large depths")
    if spec.get("lens") == "tangential":
        words.append("a lens with tangential terms p1, p2")
    if spec.get("lens") == "radial_k3":
        words.append("a lens with k3 (the r^6 term)")
    if spec.get("region") == "image":
        words.append("the whole image, corners included, where the distortion is strongest")
    if spec.get("lens") == "none":
        words.append("no distortion: the answer is the input (or the identity map)")
    if spec.get("alpha") is not None:
        words.append(f"a rectified camera new_K != K (alpha = {num(spec['alpha'])})")
    if func == "intrinsic_constraints" and spec.get("random_H"):
        words.append("random 3x3 matrices: rows v12 and v11 - v22 of eqs. (12)-(13) for any H")
    if spec.get("views") == 3 and func == "intrinsics_from_homographies":
        words.append("the minimal 3 views")
    if spec.get("n") == 4 and func == "estimate_homography":
        words.append("the minimal 4 correspondences")
    if func == "camera_height_pitch":
        words.append("robot cameras at other heights and pitches: return [height in metres, pitch in degrees "
                     "below the horizon]")
    if func == "board_ground_points":
        words.append("ground points of boards of other sizes and places: near-right corner first, "
                     "leftwards along the near row, then row by row away")
    return "; ".join(words) or spec.get("name", "")


def build_check(func: str, spec: dict, reference: Callable, tolerances: dict | None = None) -> Built:
    """Turn one check of the grading material into calls, references and a judge.

    ``reference`` is the solution notebook's function. Where the truth is known by
    construction, the solution must agree with it (else :class:`MaterialError`).
    """
    spec = typed(func, spec)  # an unknown key (camer=, atl=) is refused, named
    judge_name = spec.get("judge", "close")
    if judge_name == "precision":  # the catalogue's exact probes, judged as the self-check judges them
        return Built(func, spec["name"], float(spec.get("weight", 1.0)), [(func, a) for a in probe_args(func)],
                     [None] * len(probe_args(func)), judge_precision, {"about": spec["name"]}, form=True)
    rng = np.random.default_rng(int(spec["seed"]))
    args_list, truth = inputs_and_truth(func, spec, rng)
    refs = []
    for args, true in zip(args_list, truth):
        if judge_name == "raises":
            refs.append(None)
            continue
        ref = reference(*_copy(args))
        ref = tuple(np.asarray(r, float) if np.asarray(r).dtype != np.float32 else np.asarray(r) for r in ref) \
            if isinstance(ref, tuple) else np.asarray(ref)
        if true is not None and not spec.get("sigma"):
            tol_abs = 0.02 if func == "rectification_maps" else 1e-6
            why = _compare(ref, tuple(np.asarray(x) for x in true) if isinstance(true, tuple) else np.asarray(true),
                           tol_abs, 1e-6, f"the reference solution of {func}")
            if why:
                raise MaterialError(f"{spec.get('name')}: the solution disagrees with the independent reference "
                                    f"(OpenCV / ground truth): {why}")
        refs.append(ref)
    extra = {k: spec[k] for k in ("atol", "rtol", "tol", "dtype", "max_deg", "t_rel") if k in spec}
    extra["about"] = about(func, spec)
    built = Built(func, spec["name"], float(spec.get("weight", 1.0)), [(func, a) for a in args_list], refs,
                  JUDGES[judge_name], extra, form=judge_name in FORM_JUDGES)
    if judge_name.startswith("truth_"):
        extra["truth"] = truth
        extra["tolerance"] = (tolerances or {}).get(shape_key(func, spec))
        if not extra["tolerance"]:
            raise MaterialError(f"{spec.get('name')}: no derived tolerance for this noisy check in "
                                "grading/tolerances.json; run python -m dtscal_lib.grading.tolerances --write")
        _check_reference(built, refs)
    return built


def _check_reference(built: Built, refs: list) -> None:
    """The reference solution must pass its own noisy check (else the tolerance or the solution is wrong)."""
    frac, why = built.judge(built, CheckRun(calls=[Call(ok=True, value=r) for r in refs]))
    if frac < 1:
        raise MaterialError(f"{built.name}: the reference solution fails its own noisy check: {why}")
