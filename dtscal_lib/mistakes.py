"""The mistake catalogue (probes, mistakes, equations): how a wrong answer differs from the right one.

Both wings import it: the self-checks (``dtscal_lib.teaching.selfcheck``) and the grader
(``dtscal_lib.grading``); it imports neither.

A student's function is run on a few public *probe* inputs. Its answers are compared with
the answers of *mistake models*: small, deliberately wrong versions of each exercise
(no perspective division, R transposed, p1 and p2 swapped...). When the student's answers
match one model on every probe (and the right answer does not), that mistake is named,
with the equation of the activity text to look at. The code is never read; only answers
are compared, so the same diagnosis serves the public self-checks (which call the
function directly) and the grader (which runs it in a sandbox and sends back the answers).

The right answers here come from OpenCV and the kit's camera model, never from the
solution notebooks.

>>> d = diagnose_function("project_points", lambda K, R, t, X: ((X @ R.T + t) @ K.T)[:, :2])
>>> d.key
'no_perspective_division'
>>> print(d.line())  # doctest: +ELLIPSIS
diagnosis: no perspective division: divide the homogeneous pixel K (R X + t) by its third coordinate ...
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable

import cv2
import numpy as np

from . import duckietown as dt
from .boards import Board, ground_points
from .exercise_rules import PRECISION_RTOL, float32_sized, relative_error
from .camera import intrinsic_matrix, new_camera_matrix, normalized_to_pixel
from .camera import undistort_normalized as _newton_undistort
from .homography import apply_homography
from .poses import board_homography, random_board_pose

__all__ = ["Mistake", "diagnose", "diagnose_function", "probe_args", "MISTAKES", "FUNCTIONS"]


@dataclass(frozen=True)
class Mistake:
    """A recognised mistake: ``key`` (stable id), ``text`` (what and what to do), ``equation``."""

    key: str
    text: str
    equation: str

    def line(self) -> str:
        """The one line shown before the case list."""
        return f"diagnosis: {self.text} (activity text, {self.equation})"


# --------------------------------------------------------------------------- probe inputs
#: the camera of the probes: the self-checks' skewed camera (``selfcheck.projection.K_SKEWED``)
K_PROBE = intrinsic_matrix(312.0, 318.0, 327.0, 241.0, skew=6.0)


def raw_dlt(src, dst) -> np.ndarray:
    """The DLT without normalization (the mistake model for "no normalization"; to recognise it, not to solve
    the exercise)."""
    rows = []
    for (x, y), (u, v) in zip(src, dst):
        rows.append([x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, -u])
        rows.append([0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, -v])
    h = np.linalg.svd(np.asarray(rows))[2][-1].reshape(3, 3)
    return h / h[2, 2]


def _pose(seed: int, distance: float = 0.6):
    return random_board_pose(np.random.default_rng(seed), tilt_deg=(20.0, 35.0), distance=distance)


def _views(K, n, seed):
    """Exact board homographies of ``n`` tilted views (H = K [r1 r2 t], H[2, 2] = 1), poses."""
    rng = np.random.default_rng(seed)
    poses = [random_board_pose(rng, tilt_deg=(15.0, 40.0), distance=(0.35, 0.7), spread=(0.2, 0.15), axis_z=0.3)
             for _ in range(n)]
    return [(board_homography(K, R, t), R, t) for R, t in poses]


def _homog(H, pts, divide=True):
    """``H`` applied to ``pts``: the library's (right) answer, or the mistake of keeping x and y undivided."""
    if divide:
        return apply_homography(np.asarray(H, float), pts)
    return (np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(H, float).T)[:, :2]


def _hartley(p):
    c = p.mean(axis=0)
    s = np.sqrt(2.0) / np.mean(np.hypot(*(p - c).T))
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


@lru_cache(maxsize=None)
def _probes(func: str) -> tuple:
    rng = np.random.default_rng(900)
    if func == "project_points":
        R, t = _pose(901)
        X = np.column_stack([rng.uniform(-0.15, 0.15, 8), rng.uniform(-0.1, 0.1, 8), rng.uniform(-0.05, 0.05, 8)])
        return ((K_PROBE, R, t, X),)
    if func in ("apply_homography", "pixel_to_ground"):
        H = _views(K_PROBE, 1, 902)[0][0] @ np.diag([1.0, 1.3, 1.0])
        H = H * 2.5  # H[2, 2] != 1, so code assuming w = 1 shows
        pts = np.column_stack([rng.uniform(-0.2, 0.3, 7), rng.uniform(-0.1, 0.2, 7)])
        if func == "pixel_to_ground":
            H, pts = np.linalg.inv(H) * 3.0, _homog(H, pts)
        return ((H, pts),)
    if func == "estimate_homography":
        H, _, _ = _views(K_PROBE, 1, 903)[0]
        src = np.column_stack([rng.uniform(0.0, 0.2, 12), rng.uniform(0.0, 0.15, 12)])
        exact = (src, _homog(H, src))
        big_src = np.column_stack([rng.uniform(40, 600, 30), rng.uniform(40, 440, 30)]) * 5 + 2.0e4
        A = np.array([[0.2 / 2800, 0, -2.0e4 * 0.2 / 2800], [0, 0.15 / 2000, -2.0e4 * 0.15 / 2000], [0, 0, 1.0]])
        big_dst = _homog(H @ A, big_src) + rng.normal(0.0, 1.0, size=(30, 2))
        return (exact, (big_src, big_dst))
    if func == "intrinsic_constraints":
        H = rng.normal(size=(3, 3)) * np.array([[300.0], [300.0], [1.0]])
        return ((H,), (_views(K_PROBE, 1, 904)[0][0],))
    if func == "intrinsics_from_homographies":
        return (([v[0] for v in _views(K_PROBE, 5, 905)],),)
    if func == "extrinsics_from_homography":
        H, R, t = _views(K_PROBE, 1, 906)[0]
        obj = np.array([[x, y] for y in range(5) for x in range(7)], float) * 0.031
        img = _homog(H, obj) + rng.normal(0.0, 1.0, size=(len(obj), 2))
        H_noisy = cv2.findHomography(obj, img, 0)[0]
        return ((K_PROBE, -2.0 * H), (K_PROBE, H_noisy))
    if func in ("distort_normalized", "undistort_normalized"):
        xy = rng.uniform(-0.6, 0.6, size=(12, 2))
        d = np.array([-0.21, 0.045, 0.012, -0.009, -0.006])
        if func == "undistort_normalized":
            d_wide = dt.default_dist()
            K = dt.default_K()
            corners = np.array([[0.0, 0.0], [639.0, 0.0], [639.0, 479.0], [0.0, 479.0], [320.0, 240.0]])
            far = (np.column_stack([corners, np.ones(5)]) @ np.linalg.inv(K).T)[:, :2]
            return ((_cv_distort(xy, d), d), (far, d_wide))
        return ((xy, d),)
    if func == "rectification_maps":
        K = intrinsic_matrix(180.0, 176.0, 161.0, 98.0, skew=0.0)
        d = np.array([-0.2, 0.04, 0.01, -0.008, 0.0])
        return ((K, d, new_camera_matrix(K, d, (320, 200), 0.6), (320, 200)),)
    if func == "board_ground_points":
        return ((4, 3, 0.05, 0.3, -0.2), (3, 6, 0.02, 0.1, 0.05))
    if func == "camera_height_pitch":
        K = dt.default_P()[:, :3]
        return ((robot_ground_homography(K, 0.104, 18.0, yaw_deg=0.8) * 3.0, K),
                (robot_ground_homography(K, 0.15, 31.0, yaw_deg=-2.0, x=0.03) * -0.5, K),
                # pitched UP (a negative pitch below the horizon): shows abs() on the pitch
                (robot_ground_homography(K, 0.12, -9.0, yaw_deg=1.5, x=0.05) * 1.7, K))
    raise KeyError(func)


def robot_ground_homography(K, height: float, pitch_deg: float, *, yaw_deg: float = 0.0, x: float = 0.06):
    """The ground homography (rectified pixel -> ground metres) of a camera ``height`` metres above the ground,
    ``x`` ahead of the axle, pitched down by ``pitch_deg`` and turned left by ``yaw_deg``, built by hand."""
    p, y = np.radians(pitch_deg), np.radians(yaw_deg)
    ahead = np.array([np.cos(p) * np.cos(y), np.cos(p) * np.sin(y), -np.sin(p)])
    right = np.array([np.sin(y), -np.cos(y), 0.0])
    R = np.vstack([right, np.cross(ahead, right), ahead])  # ground (x fwd, y left, z up) -> camera
    t = -R @ np.array([x, 0.0, height])
    H = np.linalg.inv(np.asarray(K, float) @ np.column_stack([R[:, 0], R[:, 1], t]))
    return H / H[2, 2]


def _PROBE_POSE():
    """The true pose of the exact probe of extrinsics_from_homography."""
    _, R, t = _views(K_PROBE, 1, 906)[0]
    return R, t


def probe_args(func: str) -> list[tuple]:
    """Fresh copies of the probe inputs of ``func`` (a list of argument tuples)."""
    return [tuple(np.array(a, copy=True) if isinstance(a, np.ndarray) else
                  [np.array(x, copy=True) for x in a] if isinstance(a, list) else a for a in args)
            for args in _probes(func)]


# --------------------------------------------------------------------------- mistake models
# Right answers come from OpenCV, the kit's library or the probes' ground truth. A mistake
# is modelled as the right answer on transformed inputs (R.T for R, -t for t...), a
# transformed right answer (columns swapped, points reordered), or, for Zhang's closed
# form and the pose, a predicate on how the answer differs from the truth.
def _cv_distort(xy, d):
    X = np.column_stack([xy, np.ones(len(xy))])
    return cv2.projectPoints(X, np.zeros(3), np.zeros(3), np.eye(3), np.asarray(d, float))[0].reshape(-1, 2)


def _normalized(R, t, X):
    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.reshape(t, (1, 3))
    return Xc[:, :2] / Xc[:, 2:]


def _project(K, R, t, X):
    """Pixels by the kit's camera model (normalized coordinates, then K with skew)."""
    return normalized_to_pixel(_normalized(R, t, X), K)


def _undivided(K, R, t, X):
    """The homogeneous pixel before its division: pixel times depth."""
    Xc = np.asarray(X, float) @ np.asarray(R, float).T + np.reshape(t, (1, 3))
    return _project(K, R, t, X) * Xc[:, 2:]


def _noskew(K):
    K = np.array(K, float)
    K[0, 1] = 0.0
    return K


def _homog_undivided(H, pts):
    pts = np.asarray(pts, float)
    w = (np.asarray(H, float)[2, :2] @ pts.T + H[2, 2]).reshape(-1, 1)
    return _homog(H, pts) * w


def _constraints(H, combine=np.subtract):
    """Rows of V by what they mean: column k holds the constraints for b = e_k."""
    H = np.asarray(H, float)
    h1, h2 = H[:, 0], H[:, 1]
    cols = []
    for k, (i, j) in enumerate([(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)]):
        B = np.zeros((3, 3))
        B[i, j] = B[j, i] = 1.0
        cols.append([h1 @ B @ h2, combine(h1 @ B @ h1, h2 @ B @ h2)])
    return np.array(cols).T


def _maps(K, d, new_K, size):
    return cv2.initUndistortRectifyMap(np.asarray(K, float), np.asarray(d, float), None, np.asarray(new_K, float),
                                       tuple(int(s) for s in size), cv2.CV_32FC1)


def _maps_in_pixels(K, d, new_K, size):
    w, h = (int(n) for n in size)
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    xy_d = _cv_distort(np.column_stack([u.ravel(), v.ravel()]), d)
    return xy_d[:, 0].reshape(h, w).astype(np.float32), xy_d[:, 1].reshape(h, w).astype(np.float32)


def _ground(cols, rows, sq, x0, y0):
    return ground_points(Board(int(cols), int(rows), float(sq)), x0, y0)


def _ground_reordered(cols, rows, sq, x0, y0, how):
    g = _ground(cols, rows, sq, x0, y0).reshape(int(rows), int(cols), 2)
    return {"col": g.transpose(1, 0, 2), "left": g[:, ::-1], "far": g[::-1]}[how].reshape(-1, 2)


def _radial_in_r(xy, d):
    """The plumb_bob radial factor evaluated at r instead of r^2 (tangential part from OpenCV)."""
    d = np.asarray(d, float)
    r = np.hypot(xy[:, 0], xy[:, 1])[:, None]
    tangential = _cv_distort(xy, [0.0, 0.0, d[2], d[3], 0.0]) - xy
    return xy * (1 + d[0] * r + d[1] * r ** 2 + d[4] * r ** 3) + tangential


def _with(d, **changes):
    d = np.array(d, float)
    for k, v in changes.items():
        d["k1 k2 p1 p2 k3".split().index(k)] = v
    return d


def _fixed_point(xy_d, d, n, divide=True):
    """n plain fixed-point steps, by OpenCV's distortion split into its radial and tangential parts:
    ``x <- (x_d - tangential(x)) / radial(x)`` (``divide``), or ``x <- x + (x_d - distort(x))``."""
    d = np.asarray(d, float)
    xy = np.array(xy_d, float)
    for _ in range(n):
        if not divide:
            xy = xy + (xy_d - _cv_distort(xy, d))
            continue
        tangential = _cv_distort(xy, [0.0, 0.0, d[2], d[3], 0.0]) - xy
        scaled = _cv_distort(xy, [d[0], d[1], 0.0, 0.0, d[4]])
        big = np.abs(xy[:, 0]) >= np.abs(xy[:, 1])
        radial = np.where(big, scaled[:, 0] / np.where(big, xy[:, 0], 1.0), scaled[:, 1] / np.where(big, 1.0, xy[:, 1]))
        xy = (xy_d - tangential) / radial[:, None]
    return xy


def _M(key, text, eq):
    return Mistake(key, text, eq)


EQ12 = "eq. (1)-(2)"
EQ6 = "eq. (6)"
EQ36 = "eq. (3)-(6)"
EQ1213 = "eq. (12)-(13)"
PLUMB = "the plumb_bob model"

#: the correct answer, then (mistake, wrong answer) per exercise function; None marks the
#: functions whose mistakes are recognised by predicates (see _PREDICATES)
MISTAKES: dict[str, tuple[Callable, list[tuple[Mistake, Callable | None]]]] = {
    "project_points": (_project, [
        (_M("no_perspective_division", "no perspective division: divide the homogeneous pixel K (R X + t) by its "
            "third coordinate", EQ12), _undivided),
        (_M("R_transposed", "R is transposed: with points as rows the camera frame is X @ R.T + t", EQ12),
         lambda K, R, t, X: _project(K, R.T, t, X)),
        (_M("K_transposed", "K is transposed: with points as rows the pixels are Xc @ K.T", EQ12),
         lambda K, R, t, X: _homog(np.asarray(K).T, _normalized(R, t, X))),
        (_M("t_subtracted", "t is subtracted: the camera frame is R X + t, not R X - t", EQ12),
         lambda K, R, t, X: _project(K, R, -np.asarray(t), X)),
        (_M("uv_swapped", "u and v are swapped: column 0 is u (horizontal, from fx, s, cx), column 1 is v", EQ12),
         lambda K, R, t, X: _project(K, R, t, X)[:, ::-1]),
        (_M("skew_dropped", "the skew s = K[0, 1] is dropped: multiply by the whole K", EQ12),
         lambda K, R, t, X: _project(_noskew(K), R, t, X)),
    ]),
    "apply_homography": (_homog, [
        (_M("H_transposed", "H is transposed: with points as rows the product is [x, y, 1] @ H.T", EQ6),
         lambda H, p: _homog(H.T, p)),
        (_M("no_division", "no division when applying H: divide u and v by the third coordinate w", EQ6),
         _homog_undivided),
        (_M("H_inverted", "H is inverted: apply H itself, it maps the points forward", EQ6),
         lambda H, p: _homog(np.linalg.inv(H), p)),
        (_M("uv_swapped", "the two output columns are swapped", EQ6), lambda H, p: _homog(H, p)[:, ::-1]),
    ]),
    "pixel_to_ground": (_homog, [
        (_M("H_transposed", "H is transposed in pixel_to_ground: ground = H [u, v, 1]^T, with points as rows "
            "[u, v, 1] @ H.T", EQ6), lambda H, p: _homog(H.T, p)),
        (_M("no_division", "no division in pixel_to_ground: divide by the third homogeneous coordinate", EQ6),
         _homog_undivided),
        (_M("H_inverted", "H is inverted: the ground homography already maps pixels to the ground", EQ6),
         lambda H, p: _homog(np.linalg.inv(H), p)),
        (_M("axes_swapped", "the ground axes are swapped: column 0 is x (forward), column 1 is y (left)", EQ6),
         lambda H, p: _homog(H, p)[:, ::-1]),
    ]),
    "estimate_homography": (lambda s, d: _fit_variant(s, d, "right"), [
        (_M("H_transposed", "H is transposed: reshape h row by row (h.reshape(3, 3)), H maps [x, y, 1]^T", EQ36),
         lambda s, d: _fit_variant(s, d, "transposed")),
        (_M("H_inverted", "H is inverted: it must map src to dst, not dst to src", EQ36),
         lambda s, d: _fit_variant(s, d, "inverted")),
        (_M("not_scaled", "H is not scaled: divide by H[2, 2] at the end so that H[2, 2] = 1", EQ36),
         lambda s, d: _fit_variant(s, d, "unscaled")),
        (_M("H_transposed", "H is transposed: reshape h row by row (h.reshape(3, 3)), H maps [x, y, 1]^T", EQ36),
         lambda s, d: _fit_variant(s, d, "transposed_n")),
        (_M("bad_denormalization", "bad denormalization: undo the normalization as H = inv(T_dst) @ H_n @ T_src",
            EQ36), lambda s, d: _fit_variant(s, d, "bad_denorm")),
        (_M("bad_denormalization", "bad denormalization: undo the normalization as H = inv(T_dst) @ H_n @ T_src",
            EQ36), lambda s, d: _fit_variant(s, d, "no_denorm")),
        (_M("denormalization_order", "de-normalization in the wrong order: H_n maps normalized src to normalized "
            "dst, so H = inv(T_dst) @ H_n @ T_src (not inv(T_src) @ H_n @ T_dst)", EQ36),
         lambda s, d: _fit_variant(s, d, "swapped_denorm")),
        (_M("no_normalization", "no normalization: without Hartley's normalization the DLT's answer depends on "
            "where the origin is and what unit the points use, and it loses precision far from the origin; centre "
            "and scale both point sets first", EQ36),
         lambda s, d: raw_dlt(s, d)),
    ]),
    "intrinsic_constraints": (_constraints, [
        (_M("rows_not_columns", "v_ij built from the rows of H: h1 and h2 are the COLUMNS H[:, 0], H[:, 1]",
            EQ1213), lambda H: _constraints(np.asarray(H).T)),
        (_M("second_as_sum", "the second constraint as a sum: row 1 is v11 - v22 (h1^T B h1 = h2^T B h2)",
            "eq. (13)"), lambda H: _constraints(H, combine=np.add)),
        (_M("b_order", "b's elements in the wrong order: b = (B11, B12, B22, B13, B23, B33)", EQ1213),
         lambda H: _constraints(H)[:, [0, 1, 3, 2, 4, 5]]),
        (_M("b_order", "b's elements in the wrong order: b = (B11, B12, B22, B13, B23, B33)", EQ1213),
         lambda H: _constraints(H)[:, [0, 2, 1, 3, 4, 5]]),
        (_M("rows_swapped", "the two rows are swapped: row 0 is v12 (eq. 12), row 1 is v11 - v22 (eq. 13)",
            EQ1213), lambda H: _constraints(H)[::-1]),
    ]),
    "intrinsics_from_homographies": (lambda Hs: K_PROBE, [
        (_M("lambda_ignored", "lambda ignored: B = lambda K^-T K^-1 is known up to scale; compute lambda and use "
            "it in fx, fy, s, cx", EQ1213), None),
        (_M("skew_dropped", "the skew is dropped: K[0, 1] = s = -B12 fx^2 fy / lambda", EQ1213), None),
        (_M("principal_point_formula", "principal point formula slip: only cx is wrong; cx = s cy / fy - B13 "
            "fx^2 / lambda (check the skew term s cy / fy)", EQ1213), None),
        (_M("skew_formula", "skew formula slip: s = -B12 fx^2 fy / lambda (sign)", EQ1213), None),
    ]),
    "extrinsics_from_homography": (None, [
        (_M("not_orthonormalized", "R is not orthonormalized: replace [r1 r2 r1 x r2] by the nearest rotation "
            "U @ Vt from its SVD", EQ36), None),
        (_M("board_behind", "the board is behind the camera (sign of t): H has any sign; if t_z < 0, flip the "
            "sign of lambda", EQ36), None),
    ]),
    "distort_normalized": (_cv_distort, [
        (_M("tangential_swapped", "tangential terms swapped: x_d gets 2 p1 x y + p2 (r^2 + 2 x^2), y_d gets "
            "p1 (r^2 + 2 y^2) + 2 p2 x y", PLUMB), lambda xy, d: _cv_distort(xy, _with(d, p1=d[3], p2=d[2]))),
        (_M("radial_in_r", "radial terms in r instead of r^2: 1 + k1 r^2 + k2 r^4 + k3 r^6", PLUMB), _radial_in_r),
        (_M("k3_ignored", "k3 ignored: dist = (k1, k2, p1, p2, k3), k3 multiplies r^6", PLUMB),
         lambda xy, d: _cv_distort(xy, _with(d, k3=0.0))),
    ]),
    "undistort_normalized": (lambda xy, d: _newton_undistort(xy, d), [
        (_M("fixed_iterations", "a fixed small number of undistortion iterations: iterate until "
            "distort(x) matches x_d (about 1e-12), and use Newton's method where the fixed point stalls",
            PLUMB), None),
    ]),
    "rectification_maps": (_maps, [
        (_M("new_K_ignored", "new_K ignored: back-project rectified pixels with new_K^-1, distort, project with K",
            PLUMB), lambda K, d, nK, size: _maps(K, d, K, size)),
        (_M("distort_pixels", "distortion applied in pixels instead of normalized coordinates: go pixel -> "
            "new_K^-1 -> distort -> K", PLUMB), _maps_in_pixels),
        (_M("maps_swapped", "map_x and map_y swapped: map_x holds the source x (column) coordinate", PLUMB),
         lambda K, d, nK, size: _maps(K, d, nK, size)[::-1]),
        (_M("maps_transposed", "the maps are transposed: they are (height, width) arrays, map_x[v, u]", PLUMB),
         lambda K, d, nK, size: tuple(m.T for m in _maps(K, d, nK, size))),
        (_M("maps_dtype", "the maps have the wrong dtype: cv2.remap wants float32", PLUMB),
         lambda K, d, nK, size: tuple(m.astype(np.float64) for m in _maps(K, d, nK, size))),
    ]),
    "board_ground_points": (_ground, [
        (_M("axes_swapped", "ground axes swapped: column 0 is x (forward), column 1 is y (left)", EQ6),
         lambda *a: _ground(*a)[:, ::-1]),
        (_M("column_order", "corners in column order: go along the near row first (k % cols across, k // cols "
            "away)", EQ6), lambda *a: _ground_reordered(*a, "col")),
        (_M("from_left", "corners starting from the left: corner 0 is the near-RIGHT corner and y grows to the "
            "left", EQ6), lambda *a: _ground_reordered(*a, "left")),
        (_M("from_far_row", "corners starting from the far row: corner 0 is on the NEAR row (x = x0), rows go "
            "away from the robot", EQ6), lambda *a: _ground_reordered(*a, "far")),
        (_M("from_far_left", "corners starting from the far-left corner: corner 0 is the near-RIGHT corner (x0, y0)",
            EQ6), lambda *a: _ground(*a)[::-1]),
        (_M("off_by_one_square", "ground points off by one square: corner 0 is at (x0, y0) itself", EQ6),
         lambda c, r, sq, x0, y0: _ground(c, r, sq, x0 + sq, y0)),
        (_M("off_by_one_square", "ground points off by one square: corner 0 is at (x0, y0) itself", EQ6),
         lambda c, r, sq, x0, y0: _ground(c, r, sq, x0, y0 + sq)),
    ]),
}
def _height_pitch(H, K) -> np.ndarray:
    from .ground import camera_pose_from_homography

    pose = camera_pose_from_homography(np.asarray(H, float), np.asarray(K, float))
    return np.array([pose["height_m"], pose["pitch_down_deg"]])


EQ_GROUND = "eq. (5)-(6) with the ground as the plane"
MISTAKES["camera_height_pitch"] = (_height_pitch, [
    (_M("height_sign", "the height has the wrong sign: the camera centre is C = -R^T t in the robot frame, whose z "
        "axis points up, so a camera above the ground has C_z > 0", EQ_GROUND),
     lambda H, K: _height_pitch(H, K) * [-1.0, 1.0]),
    (_M("pitch_radians", "the pitch is in radians: return degrees (math.degrees)", EQ_GROUND),
     lambda H, K: _height_pitch(H, K) * [1.0, np.pi / 180.0]),
    (_M("pitch_sign", "the pitch has the wrong sign: it is how far the optical axis points BELOW the horizon, "
        "asin(-R[2, 2]) (positive for a camera looking down at the road)", EQ_GROUND),
     lambda H, K: _height_pitch(H, K) * [1.0, -1.0]),
    (_M("H_not_inverted", "H used where its inverse belongs: H maps pixels to the ground, so it is H^-1 = "
        "lambda K [r1 r2 t] (K^-1 H^-1, not K^-1 H)", EQ_GROUND),
     lambda H, K: _height_pitch_of(np.linalg.solve(np.asarray(K, float), np.asarray(H, float)), first=True)),
    (_M("height_from_t", "the height read from t: t is the robot's origin seen from the camera; the camera centre "
        "in the robot frame is C = -R^T t", EQ_GROUND),
     lambda H, K: _height_pitch_t(H, K)),
    # the mistakes below are derived from the equations, one step of the pipeline each: M = K^-1 H^-1 =
    # lambda [r1 r2 t], lambda = 1 / |M[:, 0]| (sign: a ground point ahead is in front of the camera),
    # R = [r1 r2 r1 x r2] made orthonormal, C = -R^T t, height = C_z, pitch = asin(-R[2, 2]) in degrees
    (_M("K_inverse_forgotten", "K^-1 forgotten: H^-1 = lambda K [r1 r2 t], so [r1 r2 t] = K^-1 H^-1 / lambda; "
        "without K^-1 the columns are in pixels, not a rotation", EQ_GROUND),
     lambda H, K: _hp(np.linalg.inv(np.asarray(H, float)))),
    (_M("K_transposed", "K transposed: solve with K itself (M = K^-1 H^-1 = np.linalg.solve(K, H^-1)), not K^T",
        EQ_GROUND), lambda H, K: _hp(np.linalg.solve(np.asarray(K, float).T, np.linalg.inv(np.asarray(H, float))))),
    (_M("t_wrong_column", "t from the wrong column: [r1 r2 t] = lambda M, so t = lambda M[:, 2] (the third "
        "column), r1 and r2 are the first two", EQ_GROUND), lambda H, K: _hp(_M_of(H, K), t_col=0)),
    (_M("t_wrong_column", "t from the wrong column: [r1 r2 t] = lambda M, so t = lambda M[:, 2] (the third "
        "column), r1 and r2 are the first two", EQ_GROUND), lambda H, K: _hp(_M_of(H, K), t_col=1)),
    (_M("lambda_from_t", "lambda from t: r1 is a unit vector, t is not, so lambda = 1 / |M[:, 0]| (or the mean of "
        "|M[:, 0]| and |M[:, 1]|), never 1 / |M[:, 2]|", EQ_GROUND), lambda H, K: _hp(_M_of(H, K), lam_col=2)),
    (_M("height_in_mm", "the height in millimetres: the ground homography is in metres, return metres", EQ_GROUND),
     lambda H, K: _height_pitch(H, K) * [1000.0, 1.0]),
    (_M("height_in_cm", "the height in centimetres: the ground homography is in metres, return metres", EQ_GROUND),
     lambda H, K: _height_pitch(H, K) * [100.0, 1.0]),
    (_M("height_is_t_z", "t_z used as the height: t is the robot's origin in CAMERA coordinates (its depth); the "
        "height is the z of the camera centre C = -R^T t in the robot frame", EQ_GROUND),
     lambda H, K: _hp(_M_of(H, K), height="t_z")),
    (_M("height_is_C_x", "C_x used as the height: the robot frame's z axis points up, so the height is C[2] "
        "(C[0] is how far ahead of the axle the camera sits)", EQ_GROUND), lambda H, K: _hp(_M_of(H, K), height="C_x")),
    (_M("C_is_minus_R_t", "C = -R t: the camera centre is C = -R^T t (R maps robot to camera coordinates, its "
        "transpose maps back)", EQ_GROUND), lambda H, K: _hp(_M_of(H, K), height="Rt")),
    (_M("pitch_from_vertical", "the pitch measured from the vertical: it is the angle BELOW THE HORIZON, "
        "asin(-R[2, 2]) = 90 deg minus the angle from the vertical", EQ_GROUND),
     lambda H, K: _height_pitch(H, K) * [1.0, -1.0] + [0.0, 90.0]),
    (_M("outputs_swapped", "the two outputs are swapped: return [height in metres, pitch in degrees]", EQ_GROUND),
     lambda H, K: _height_pitch(H, K)[::-1]),
    (_M("abs_pitch", "abs() on the pitch: a camera pitched UP has a negative pitch below the horizon; keep the "
        "sign of asin(-R[2, 2])", EQ_GROUND), lambda H, K: np.abs(_height_pitch(H, K))),
])


def _M_of(H, K) -> np.ndarray:
    """M = K^-1 H^-1 = lambda [r1 r2 t]."""
    return np.linalg.solve(np.asarray(K, float), np.linalg.inv(np.asarray(H, float)))


def _hp(M: np.ndarray, *, lam_col: int = 0, t_col: int = 2, height: str = "C_z") -> np.ndarray:
    """[height, pitch] by the pipeline of the hint (lambda from the first column, sign from a ground point 0.3 m
    ahead, R made orthonormal, C = -R^T t), with one step as a mistake names it."""
    lam = 1.0 / np.linalg.norm(M[:, lam_col])
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, t_col]
    if (0.3 * r1 + lam * M[:, 2])[2] < 0:
        r1, r2, t = -r1, -r2, -t
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Wt
    h = {"C_z": (-R.T @ t)[2], "C_x": (-R.T @ t)[0], "t_z": t[2], "Rt": (-R @ t)[2]}[height]
    return np.array([float(h), float(np.degrees(np.arcsin(np.clip(-R[2, 2], -1, 1))))])


def _rt_of(M: np.ndarray, first: bool = False):
    """[r1 r2 t] of M = lambda [r1 r2 t] (lambda from the first column, or the mean of both), R made orthonormal.
    Applied to a matrix that is not of that form (a mistake model), the two choices differ: the usual one, the
    first column (the self-check's hint), is the one modelled."""
    lam = 1.0 / np.linalg.norm(M[:, 0]) if first else 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    if (0.3 * r1 + t)[2] < 0:
        r1, r2, t = -r1, -r2, -t
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    return U @ Wt, t


def _height_pitch_of(M: np.ndarray, first: bool = False) -> np.ndarray:
    R, t = _rt_of(M, first)
    return np.array([float((-R.T @ t)[2]), float(np.degrees(np.arcsin(np.clip(-R[2, 2], -1, 1))))])


def _height_pitch_t(H, K) -> np.ndarray:
    R, t = _rt_of(np.linalg.solve(np.asarray(K, float), np.linalg.inv(np.asarray(H, float))))
    return np.array([float(-t[2]), float(np.degrees(np.arcsin(np.clip(-R[2, 2], -1, 1))))])


FUNCTIONS = tuple(MISTAKES)


def _fit_variant(src, dst, how):
    """Exact-data answers of right and wrong homography fits (from OpenCV's fit)."""
    H = cv2.findHomography(np.asarray(src, float), np.asarray(dst, float), 0)[0]
    H = H / H[2, 2]
    if how in ("right", "unscaled"):  # "unscaled" is compared up to scale, see diagnose
        return H
    if how == "transposed":
        return H.T / H[2, 2]
    if how == "inverted":
        Hi = np.linalg.inv(H)
        return Hi / Hi[2, 2]
    Ts, Td = _hartley(np.asarray(src, float)), _hartley(np.asarray(dst, float))
    Hn = Td @ H @ np.linalg.inv(Ts)
    Hb = {"bad_denorm": Ts @ Hn @ np.linalg.inv(Td), "no_denorm": Hn, "swapped_denorm": np.linalg.inv(Ts) @ Hn @ Td,
          "transposed_n": np.linalg.inv(Td) @ Hn.T @ Ts}[how]
    return Hb / Hb[2, 2]


def _k_predicates(K, K_true) -> str | None:
    """Which Zhang slip turns the true K into ``K`` (by the entries that differ, and how)."""
    f = lambda a, b: abs(a - b) <= 1e-5 * abs(K_true[0, 0])  # noqa: E731
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    t_fx, t_s, t_cx, t_fy, t_cy = K_true[0, 0], K_true[0, 1], K_true[0, 2], K_true[1, 1], K_true[1, 2]
    if f(cy, t_cy) and not f(fx, t_fx) and abs(fx / t_fx - fy / t_fy) < 1e-6:
        return "lambda_ignored"
    if f(fx, t_fx) and f(fy, t_fy) and f(cy, t_cy):
        if abs(s) < 1e-9 and t_s != 0:
            return "skew_dropped"
        if f(s, t_s) and not f(cx, t_cx):  # only cx is wrong: its formula (the skew term) slipped
            return "principal_point_formula"
        if f(s, -t_s) and t_s != 0:
            return "skew_formula"
    return None


def _pose_predicates(args_list, got) -> str | None:
    """Not orthonormalized (the noisy probe) or the board behind the camera (the negative-scale probe)."""
    (K0, H0), (K1, H1) = args_list
    R_true, t_true = _PROBE_POSE()
    parts = got[0]
    if len(parts) == 2 and parts[0].shape == (3, 3) and parts[1].size == 3:
        R, t = parts[0].astype(float), parts[1].astype(float).ravel()
        if np.allclose(t, -t_true, rtol=1e-6, atol=1e-9) and np.allclose(R[:, 2], R_true[:, 2], atol=1e-6):
            return "board_behind"
    parts = got[-1]
    if len(parts) == 2 and parts[0].shape == (3, 3):
        R = parts[0].astype(float)
        if np.all(np.isfinite(R)) and np.abs(R.T @ R - np.eye(3)).max() > 1e-6:
            return "not_orthonormalized"
    return None


# --------------------------------------------------------------------------- matching
def _as_arrays(value) -> list[np.ndarray] | None:
    parts = value if isinstance(value, (tuple, list)) and len(value) in (2, 3) and not np.isscalar(value[0]) \
        and np.ndim(value[0]) >= 1 else (value,)
    out = []
    for p in parts:
        try:
            a = np.asarray(p)
            out.append(a if a.dtype.kind in "fiu" else np.asarray(p, dtype=np.float64))
        except Exception:
            return None
    return out


def _close(got: list, want: list, rtol: float = 1e-5, dtype: bool = False) -> bool:
    if len(got) != len(want):
        return False
    for g, w in zip(got, want):
        w = np.asarray(w)
        if g.shape != w.shape or (dtype and g.dtype != w.dtype):
            return False
        g64, w64 = g.astype(np.float64), w.astype(np.float64)
        if not np.all(np.isfinite(g64)):
            return False
        scale = max(float(np.abs(w64).max(initial=0.0)), 1e-12)
        if not np.all(np.abs(g64 - w64) <= rtol * scale):
            return False
    return True


def _same_up_to_scale(got: list, want: list) -> bool:
    g, w = got[0].astype(np.float64).ravel(), np.asarray(want[0], float).ravel()
    if g.shape != w.shape or not np.all(np.isfinite(g)):
        return False
    k = float(g @ w) / float(w @ w)
    return abs(k - 1.0) > 1e-6 and abs(k) > 1e-12 and np.allclose(g / k, w, rtol=1e-5, atol=1e-7 * np.abs(w).max())


def diagnose(func: str, args_list: list[tuple], outputs: list[Any]) -> Mistake | None:
    """The mistake that explains ``outputs`` (the student's answers on ``args_list``), or None.

    ``outputs[i]`` is what the function returned for ``args_list[i]`` (an exception object
    when it raised). None when the answers are right, match no model, or any probe raised.
    """
    if func not in MISTAKES or not outputs or any(isinstance(o, BaseException) for o in outputs):
        return None
    right, models = MISTAKES[func]
    got = [_as_arrays(o) for o in outputs]
    if any(g is None for g in got):
        return None
    by_key = {m.key: m for m, _ in models}
    if func == "undistort_normalized":
        return _diagnose_undistort(args_list, got, models[0][0])
    if func == "extrinsics_from_homography":
        return by_key.get(_pose_predicates(args_list, got) or "")
    if func == "intrinsics_from_homographies":
        K = got[0][0]
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            return None
        return by_key.get(_k_predicates(K.astype(float), K_PROBE) or "")
    wants = [_as_arrays(right(*a)) for a in args_list]
    dtype = func == "rectification_maps"
    if all(_close(g, w, dtype=dtype) for g, w in zip(got, wants)):
        return None
    # the wrong fits of estimate_homography are modelled on the noise-free probe only
    exact = slice(0, 1) if func == "estimate_homography" else slice(None)
    for mistake, model in models:
        if mistake.key == "not_scaled":
            if all(_same_up_to_scale(g, w) for g, w in zip(got[exact], wants[exact])):
                return mistake
            continue
        try:
            wrong = [_as_arrays(model(*a)) for a in args_list]
        except Exception:  # a model that does not apply to these inputs
            continue
        if mistake.key == "no_normalization":  # noise-free data hides it; the noisy far probe shows it
            if _close(got[-1], wrong[-1], rtol=1e-4) and not _close(got[-1], wants[-1], rtol=1e-4):
                return mistake
            continue
        if all(_close(g, w, dtype=dtype) for g, w in zip(got[exact], wrong[exact])):
            return mistake
    if dtype:  # the maps: a mistake of values and a mistake of dtype together
        for mistake, model in models:
            try:
                wrong = [_as_arrays(model(*a)) for a in args_list]
            except Exception:
                continue
            if mistake.key != "maps_dtype" and all(_close(g, w) for g, w in zip(got, wrong)):
                return Mistake(mistake.key + "+dtype", mistake.text + "; and the maps should be float32 (cv2.remap "
                               "wants float32)", mistake.equation)
    return None


def _diagnose_undistort(args_list, got, mistake):
    """A fixed small number of fixed-point steps: the student's answer equals n steps, n <= 20."""
    for (xy_d, d), g in zip(args_list, got):
        xy_d = np.asarray(xy_d, float)
        truth = _newton_undistort(xy_d, d)
        if _close(g, [truth], rtol=1e-7):
            continue
        for n in range(1, 21):
            if any(_close(g, [_fixed_point(xy_d, d, n, divide)], rtol=1e-9) for divide in (True, False)):
                return mistake
        if _close(g, [_fixed_point(xy_d, d, 500)], rtol=1e-6):  # converged fixed point, stalled at the corners
            return Mistake("fixed_point_stalls", "the plain fixed-point iteration stalls at the far corners of a wide "
                           "lens: use Newton's method with the 2x2 Jacobian of the distortion", "the plumb_bob model")
    return None


def diagnose_function(func: str, fn: Callable) -> Mistake | None:
    """Run ``fn`` on the probes of ``func`` and :func:`diagnose` its answers (the self-checks use this)."""
    args_list = probe_args(func)
    outputs = []
    for args in args_list:
        try:
            outputs.append(fn(*probe_args(func)[len(outputs)]))
        except Exception as exc:  # a raising probe gives no diagnosis
            outputs.append(exc)
    return diagnose(func, args_list, outputs)


# --------------------------------------------------------------------------- the precision contract
#: the probes of each function whose right answer is exact (the noisy ones determine no exact answer)
_EXACT_PROBES = {"estimate_homography": (0,), "extrinsics_from_homography": (0,)}
#: the maps are float32 by contract (judged to 0.01 px): no precision probe
NO_PRECISION = ("rectification_maps",)


def right_answers(func: str, args_list: list[tuple]) -> list:
    """The exact answer of each probe (None for a noisy probe)."""
    exact = _EXACT_PROBES.get(func, range(len(args_list)))
    out = []
    for i, args in enumerate(args_list):
        if i not in exact:
            out.append(None)
        elif func == "extrinsics_from_homography":
            out.append(_PROBE_POSE())
        elif func == "intrinsics_from_homographies":
            out.append(K_PROBE)
        elif func == "estimate_homography":  # the probe's true H (an exact fit reproduces it)
            H = _views(K_PROBE, 1, 903)[0][0]
            out.append(H / H[2, 2])
        elif func == "undistort_normalized":
            out.append(_newton_undistort(np.asarray(args[0], float), args[1]))
        else:
            out.append(MISTAKES[func][0](*args))
    return out


def precision_problem(func: str, args_list: list[tuple], outputs: list) -> str:
    """The precision contract (float64 inside), judged the same way by the self-check and the grader: "" when
    every exact probe's answer is within :data:`PRECISION_RTOL` of the right one, else what is wrong. A wrong
    answer (not a float32-sized difference) is left to the value checks: "" too."""
    if func in NO_PRECISION:
        return ""
    for out, want in zip(outputs, right_answers(func, args_list)):
        if want is None or isinstance(out, BaseException):
            continue
        got, wants = _as_arrays(out), _as_arrays(want)
        err = relative_error(got, wants) if got is not None and len(got) == len(wants) else None
        if err is not None and float32_sized(err):
            return (f"should be computed in float64: right to a relative {err:.1g} only, where float64 gives "
                    f"{PRECISION_RTOL:g} or better (float32 arithmetic, a rounded constant or a loose iteration "
                    "tolerance somewhere)")
    return ""

