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
from ..errors import DtscalError
from ..poses import board_homography, points_on_rays, random_board_pose
from .sandbox import CheckRun

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


# --------------------------------------------------------------------------- inputs
def _pose(rng, distance=(0.3, 0.9), max_deg=40.0):
    return random_board_pose(rng, DUCKIETOWN_BOARD, tilt_deg=(5.0, max_deg), distance=distance, spread=(0.2, 0.15))


def _img_span(K):
    return 2 * K[0, 2], 2 * K[1, 2]


def _apply(H, pts):
    return cv2.perspectiveTransform(np.asarray(pts, float).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)


def inputs_and_truth(func: str, p: dict, rng) -> tuple[list[tuple], list]:
    """The argument tuples of one check and, where known, the true answers (else None)."""
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
            H = H * rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 50.0) if p.get("random_scale") else H
            pts = np.column_stack([rng.uniform(-0.1, 0.3, n), rng.uniform(-0.1, 0.25, n)])
            if func == "pixel_to_ground":
                H, pts = np.linalg.inv(H), _apply(H, pts)
            args.append((H, pts))
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
            truth.append(H if sigma == 0 else None)
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
                H = H * rng.choice([-1.0, 1.0]) * rng.uniform(0.01, 100.0)
            Hs.append(H)
            poses.append((R, t))
        if func == "intrinsic_constraints":
            Hs = Hs if not p.get("random_H") else [rng.normal(size=(3, 3)) * [[300.0], [300.0], [1.0]]
                                                   for _ in Hs]
            return [(H,) for H in Hs], [None] * len(Hs)
        if func == "intrinsics_from_homographies":
            return [(Hs,)], [K if not sigma else None]
        return [(K.copy(), H) for H in Hs], [pose if not sigma else None for pose in poses]
    if func in ("distort_normalized", "undistort_normalized"):
        d = np.array(p["dist"], float) if "dist" in p else LENSES[p.get("lens", "duckiebot")]
        if p.get("region") == "image":  # the distorted image's pixels, corners included
            K = dt.default_K()
            us, vs = np.meshgrid(np.r_[0:640:16, 639], np.r_[0:480:16, 479])
            xy_d = (np.column_stack([us.ravel(), vs.ravel(), np.ones(us.size)]) @ np.linalg.inv(K).T)[:, :2]
            from ..camera import undistort_normalized as newton
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


def _transfer_rms(H, src, dst):
    return float(np.sqrt(np.mean(np.sum((_apply(H, src) - dst) ** 2, axis=1))))


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
            bad.append(f"case {i + 1}: {why}" + (f" (returned {c.note})" if c.note else ""))
    ok = len(calls) - len(bad)
    return ok / len(calls), ("; ".join(bad[:2]) + (f" (+{len(bad) - 2} more)" if len(bad) > 2 else "")) if bad else ""


def judge_unchanged(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    for c, args in zip(calls, built.calls):
        if not c.ok:
            return 0.0, f"raised {c.error}"
        for k, a in enumerate(args[1]):
            if isinstance(a, np.ndarray):
                after = c.args_after[k] if c.args_after and k < len(c.args_after) else None
                if not isinstance(after, np.ndarray) or after.shape != a.shape or not np.array_equal(after, a):
                    return 0.0, f"the function changed its input argument {k + 1}; work on a copy"
    return 1.0, ""


def judge_dtype(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    want = built.extra.get("dtype", "float64")
    for c, ref in zip(calls, built.refs):
        if not c.ok:
            return 0.0, f"raised {c.error}"
        parts, refs = _arrays(c.value), (list(ref) if isinstance(ref, tuple) else [ref])
        if parts is None or len(parts) != len(refs):
            return 0.0, f"should return {len(refs)} numpy array(s), got {_describe_value(c.value)}"
        for g, r in zip(parts, refs):
            if g.shape != np.shape(r):
                return 0.0, f"should return shape {np.shape(r)}, got {g.shape}"
            if str(g.dtype) != want:
                return 0.0, f"should return dtype {want}, got {g.dtype}"
        if c.note:
            return 0.0, f"should return a plain numpy array, got {c.note}"
    return 1.0, ""


def judge_raises(built: Built, run: CheckRun):
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    for c in calls:
        if c.ok:
            return 0.0, f"should raise ValueError (the input does not determine the answer), but returned " \
                        f"{_describe_value(c.value)}"
        if not c.error.startswith("ValueError") or "math domain error" in c.error:
            return 0.0, f"should raise ValueError saying what is wrong (check the number of views first), " \
                        f"raised {c.error}"
    return 1.0, ""


def judge_transfer(built: Built, run: CheckRun):
    """Noisy homographies: transfer error within ``tol`` of the reference fit's."""
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    tol = built.extra.get("tol", 0.01)
    bad = []
    for i, (c, (src, dst), ref_H) in enumerate(zip(calls, [a for _, a in built.calls], built.refs)):
        if not c.ok:
            bad.append(f"case {i + 1}: raised {c.error}")
            continue
        if not isinstance(c.value, np.ndarray) or c.value.shape != (3, 3) or not np.all(np.isfinite(c.value)):
            bad.append(f"case {i + 1}: expected a finite (3, 3) array, got {_describe_value(c.value)}")
            continue
        mine, ref = _transfer_rms(c.value.astype(float), src, dst), _transfer_rms(ref_H, src, dst)
        if not mine <= ref * (1 + tol) + 1e-9:
            bad.append(f"case {i + 1}: transfer error {num(mine)} px; the reference reaches {num(ref)} px "
                       f"(allowed {num(100 * tol)} % more)")
    return (len(calls) - len(bad)) / len(calls), "; ".join(bad[:2])


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


def _rotation_angle(Ra, Rb) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1.0, 1.0))))


def judge_pose(built: Built, run: CheckRun):
    """Poses from noisy homographies: a proper rotation near the reference's, t_z > 0."""
    calls, why = _calls_or_failure(built, run)
    if calls is None:
        return 0.0, why
    max_deg, t_rel = built.extra.get("max_deg", 0.5), built.extra.get("t_rel", 0.01)
    bad = []
    for i, (c, (R_ref, t_ref)) in enumerate(zip(calls, built.refs)):
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
        if orth > 1e-6 or np.linalg.det(R) < 0:
            bad.append(f"case {i + 1}: R is not a rotation (|R^T R - I| = {num(orth)}, det = {num(np.linalg.det(R))})")
        elif t[2] <= 0:
            bad.append(f"case {i + 1}: t_z = {num(t[2])} puts the board behind the camera")
        elif _rotation_angle(R, R_ref) > max_deg or np.linalg.norm(t - t_ref) > t_rel * np.linalg.norm(t_ref):
            bad.append(f"case {i + 1}: the pose is {num(_rotation_angle(R, R_ref))} deg and "
                       f"{num(np.linalg.norm(t - t_ref))} m from the reference's")
    return (len(calls) - len(bad)) / len(calls), "; ".join(bad[:2])


JUDGES = {"close": judge_close, "unchanged": judge_unchanged, "dtype": judge_dtype, "raises": judge_raises,
          "transfer": judge_transfer, "scaled": judge_scaled, "pose": judge_pose}


# --------------------------------------------------------------------------- building a check
def _copy(args):
    return tuple([np.array(x, copy=True) for x in a] if isinstance(a, list) else
                 np.array(a, copy=True) if isinstance(a, np.ndarray) else a for a in args)


def build_check(func: str, spec: dict, reference: Callable) -> Built:
    """Turn one check of the grading material into calls, references and a judge.

    ``reference`` is the solution notebook's function. Where the truth is known by
    construction, the solution must agree with it (else :class:`MaterialError`).
    """
    judge_name = spec.get("judge", "close")
    if judge_name not in JUDGES:
        raise MaterialError(f"{func}: unknown judge {judge_name!r} in the grading material")
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
        if true is not None:
            tol_abs = 0.02 if func == "rectification_maps" else 1e-6
            why = _compare(ref, tuple(np.asarray(x) for x in true) if isinstance(true, tuple) else np.asarray(true),
                           tol_abs, 1e-6, f"the reference solution of {func}")
            if why:
                raise MaterialError(f"{spec.get('name')}: the solution disagrees with the independent reference "
                                    f"(OpenCV / ground truth): {why}")
        refs.append(ref)
    extra = {k: spec[k] for k in ("atol", "rtol", "tol", "dtype", "max_deg", "t_rel") if k in spec}
    return Built(func, spec["name"], float(spec.get("weight", 1.0)), [(func, a) for a in args_list], refs,
                 JUDGES[judge_name], extra)
