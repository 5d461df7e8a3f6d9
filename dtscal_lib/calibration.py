"""Full intrinsic calibration from views of a planar target (Zhang's method).

Pipeline, for ``V`` views of a planar target (any planar point set, any unit):

1. **Check the input** at the boundary: shapes, NaN, at least 3 views, at least 4
   non-collinear points per view, planar object points, matching lengths.
2. **Homographies**: one normalized DLT per view, board plane -> pixels
   (:func:`dtscal_lib.homography.estimate_homography`).
3. **Degeneracy check**: every view gives Zhang's two constraints (activity
   text, eqs. (12)-(13)) on ``b = (B11, B12, B22, B13, B23, B33)``,
   ``B = K^-T K^-1``. If the stacked constraint matrix ``V`` (plus ``B12 = 0`` when the
   skew is not estimated) does not pin ``b`` down up to scale -- all boards parallel,
   the same pose over and over -- we stop *before* optimising garbage. A strongly
   distorted lens hides this in the homographies (parallel boards in different image
   regions look differently tilted), so after the refinement the recovered board
   normals must also spread by at least ``MIN_TILT_SPREAD_DEG``, and a focal length
   whose standard deviation exceeds ``MAX_RELATIVE_FOCAL_STD`` of it is refused too.
4. **Closed-form start**: ``b`` from the null vector of ``V``, ``K`` from ``B``
   (Zhang's appendix B, skew included), each view's ``[r1 r2 t]`` from ``K^-1 H``,
   distortion zero. If the closed form is not physical (B not positive definite,
   e.g. strong distortion and few views) we start from OpenCV's
   ``initCameraMatrix2D`` instead.
5. **Refinement**: Levenberg-Marquardt on the reprojection error over every
   parameter -- ``fx, fy, cx, cy, (s), distortion`` and 6 pose parameters per view --
   solved through the Schur complement of the block-diagonal pose part, so one step
   costs ``O(V)`` instead of ``O(V^3)``. (OpenCV's ``calibrateCamera`` solves the full
   dense system at every step: ~0.5 s for 40 views of the 7x5 board, and it cannot
   estimate skew.) A view whose error stays far above the others' gets its pose
   re-estimated by PnP with the refined camera (a nearly face-on board has two poses that
   project almost alike, and a poor start can leave one view in the flipped one), and the
   refinement goes on from there when that fits it better. Given ``initial`` (an earlier
   solution, e.g. of the same views before outliers were dropped), the refinement starts
   there instead of steps 4-5's search.
6. **Uncertainty** (:mod:`dtscal_lib.covariance`): the noise model, the Hartley-Zisserman way,
   ``sigma^2 = |e|^2 / (2N - p)`` with ``e`` all residuals, ``N`` all points and ``p`` all
   estimated parameters, covariance ``sigma^2 (J^T J)^-1`` (OpenCV's ``stdDeviationsIntrinsics``:
   ``std_noise_model``); and a sandwich over the views (close to a leave-one-view-out jackknife).
   The reported standard deviations ``std`` come from the larger of the two in every direction: on
   real photographs, whose residuals are not independent noise, the noise model alone is 2-4x too
   small. Both through the Schur complement, linear in the views.

The projection of every point of every view and its Jacobian (skew and distortion terms
included) are computed at once in numpy (``_Problem``), one vectorized Rodrigues for all poses;
the tests check them against :func:`dtscal_lib.camera.project_points` (which honours skew),
finite differences and ``cv2.Rodrigues``.

Examples
--------
>>> import numpy as np
>>> from dtscal_lib import camera, duckietown as dt
>>> from dtscal_lib.boards import DUCKIETOWN_BOARD
>>> obj = DUCKIETOWN_BOARD.object_points()
>>> poses = [([0.3, 0.1, 0.0], [-0.1, -0.06, 0.35]), ([-0.2, 0.3, 0.1], [-0.1, -0.05, 0.4]),
...          ([0.1, -0.35, -0.1], [-0.08, -0.07, 0.3]), ([-0.3, -0.2, 0.2], [-0.1, -0.04, 0.45])]
>>> img = [camera.project_points(obj, r, t, dt.default_K(), dt.default_dist()) for r, t in poses]
>>> res = calibrate([obj] * 4, img, dt.IMAGE_SIZE)
>>> bool(np.allclose(res.K, dt.default_K(), rtol=1e-6)) and res.rms < 1e-6
True
"""

from __future__ import annotations

import cv2
import numpy as np

from .camera import DIST_MODELS, KIT_SOLVER_MODELS, MODEL_COEFFS, as_K, as_points, project_points
from .closed_form import (  # noqa: F401  (re-exported: the closed form's names as they were here)
    _check_not_degenerate, _constraint_matrix, _image_normalizer, _intrinsics_from_b, _null_vector,
    _pose_from_homography, _v_row, board_normal_spread, plane_homography, zhang_closed_form)
from .covariance import rodrigues as _rodrigues  # noqa: F401
from .errors import CalibrationError, DtscalError
from .lsq import (  # noqa: F401  (re-exported: the least-squares problem's names as they were here)
    MAX_ITERATIONS, _cost, _dist_indices, _intrinsic_covariance, _normal_blocks, _param_names, _Problem, _refine,
    _schur_solve, _unpack)
from .result import CalibrationResult
from .validation import check_image_size

__all__ = ["CalibrationResult", "calibrate", "zhang_closed_form", "plane_homography", "board_normal_spread"]

#: a view needs at least this many points (a homography has 8 degrees of freedom)
MIN_POINTS_PER_VIEW = 4
#: Zhang's constraints need at least this many views
MIN_VIEWS = 3
#: boards whose recovered normals all lie within this angle (degrees) of their mean are "parallel";
#: a focal length whose standard deviation exceeds this fraction of it is not determined (limits of the
#: mathematics, named apart from the beliefs in the one table: dtscal_lib.limits)
from .limits import FOCAL_STD_UNDETERMINED as MAX_RELATIVE_FOCAL_STD  # noqa: E402
from .limits import MIN_TILT_SPREAD_DEG  # noqa: E402
#: the extent of a view's object points, in their unit: a board, not an atom or a planet
OBJECT_EXTENT_RANGE = (1e-6, 1e6)
#: image points may lie this fraction of the image size outside it (a detector never does)
IMAGE_SLACK = 0.25
#: most corners (over all views) one calibration takes: calibration needs about 1.1 kB per corner and its
#: verdict about 0.6 kB (benchmarks/bench_memory.py: 4000 views x 35 corners, +148 MB and +82-89 MB), so
#: this keeps either near 1 GB; more views than that add nothing a subset would not give
MAX_POINTS = 1_000_000


# =========================================================================== OpenCV's models
#: the flags ROS's calibrator passes for each model OpenCV calibrates (camera_calibration calibrator.py,
#: cal_fromcorners): rational_polynomial is calibrateCamera with CALIB_RATIONAL_MODEL and every k free (ROS's
#: ``-k 6``); equidistant is cv2.fisheye.calibrate, here with CALIB_RECOMPUTE_EXTRINSIC (OpenCV's fisheye
#: solver refines each pose after every intrinsic step; without it it often stops far from the optimum) and
#: CALIB_FIX_SKEW (the kit's cameras have none, and a ROS file's K keeps it 0)
#: (names of cv2 attributes, looked up when calibrating: the grader's sandbox replaces cv2's solvers by stubs)
OPENCV_FLAGS = {"rational_polynomial": ("CALIB_RATIONAL_MODEL",),
                "equidistant": ("fisheye.CALIB_RECOMPUTE_EXTRINSIC", "fisheye.CALIB_FIX_SKEW")}


def _opencv_flags(model: str) -> int:
    flags = 0
    for name in OPENCV_FLAGS[model]:
        obj = cv2
        for part in name.split("."):
            obj = getattr(obj, part)
        flags |= int(obj)
    return flags
_OPENCV_NAMES = {"rational_polynomial": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
                 "equidistant": ("k1", "k2", "k3", "k4")}


def calibrate_opencv(object_points, image_points, image_size, model: str) -> CalibrationResult:
    """Calibrate ``rational_polynomial`` or ``equidistant`` with OpenCV, as ROS's calibrator does.

    Why OpenCV's solver and not the kit's: the kit's refinement (``_Problem``) has the analytic Jacobian of
    the 5-term polynomial only; for these two models ROS's calibrator calls ``cv2.calibrateCamera`` with
    ``CALIB_RATIONAL_MODEL`` and ``cv2.fisheye.calibrate``, so using the same calls gives the robot exactly
    the calibration ROS would (OpenCV's default stopping rules, as ROS passes none). ``std`` is OpenCV's
    noise-model standard deviation for rational_polynomial
    (``calibrateCameraExtended``); ``cv2.fisheye`` reports none, so ``std`` is empty for equidistant.
    """
    if model not in OPENCV_FLAGS:
        raise CalibrationError(f"OpenCV calibrates {tuple(OPENCV_FLAGS)} here, not {model!r}")
    obj, img, size = _check_views(object_points, image_points, image_size)
    flags = _opencv_flags(model)
    obj3 = [np.column_stack([np.asarray(o, dtype=np.float64)[:, :2], np.zeros(len(o))]) for o in obj]
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in img]
    try:
        if model == "rational_polynomial":
            out = cv2.calibrateCameraExtended([o.astype(np.float32) for o in obj3],
                                              [p.astype(np.float32) for p in pts], tuple(size), None, None,
                                              flags=flags)
            rms, K, dist, rv, tv, std_i = out[0], out[1], out[2], out[3], out[4], out[5]
            dist = np.asarray(dist, dtype=np.float64).ravel()[:8]  # as ROS: dist_coeffs.flat[:8]
            names = ("fx", "fy", "cx", "cy") + _OPENCV_NAMES[model]
            std = {n: float(v) for n, v in zip(names, np.asarray(std_i).ravel()[:12])}
            method = "OpenCV's noise model (calibrateCameraExtended's stdDeviationsIntrinsics)"
        else:
            rms, K, dist, rv, tv = cv2.fisheye.calibrate([o.reshape(-1, 1, 3) for o in obj3],
                                                         [p.reshape(-1, 1, 2) for p in pts], tuple(size), None,
                                                         None, flags=flags)
            dist = np.asarray(dist, dtype=np.float64).ravel()[:4]
            std, method = {}, "none: cv2.fisheye.calibrate reports no uncertainty"
    except cv2.error as e:
        raise CalibrationError(f"OpenCV could not calibrate the {model} model on these views "
                               f"({str(e).strip().splitlines()[-1]}); collect more varied views") from None
    K = np.asarray(K, dtype=np.float64)
    rvecs = np.asarray(rv, dtype=np.float64).reshape(-1, 3)
    tvecs = np.asarray(tv, dtype=np.float64).reshape(-1, 3)
    per_view, sq = [], 0.0
    for o, p, r, t in zip(obj3, pts, rvecs, tvecs):
        e = project_points(o, r, t, K, dist, model=model) - p
        per_view.append(float(np.sqrt((e ** 2).sum() / len(p))))
        sq += float((e ** 2).sum())
    n = sum(len(p) for p in pts)
    n_params = 4 + MODEL_COEFFS[model] + 6 * len(pts)
    return CalibrationResult(
        K=K, dist=dist, rms=float(np.sqrt(sq / n)), per_view_rms=np.asarray(per_view), rvecs=rvecs, tvecs=tvecs,
        std=std, model=model, skew=False, image_size=size, n_views=len(pts), n_points=n,
        sigma=float(np.sqrt(sq / max(1, 2 * n - n_params))), object_points=[o[:, :2] for o in obj3],
        image_points=pts, std_noise_model=dict(std), std_method=method)


# =========================================================================== input checks
def _check_views(object_points, image_points, image_size):
    """Validate and convert the input.

    Returns
    -------
    obj : list of (N_i, 2) float64 board-plane points
    img : list of (N_i, 2) float64 pixels
    size : (width, height)
    """
    try:
        w, h = check_image_size(image_size, name="image_size")
    except DtscalError as e:
        raise CalibrationError(str(e)) from None
    if isinstance(object_points, np.ndarray) and object_points.ndim == 2:
        raise CalibrationError(
            "object_points must be a sequence of views (one (N, 3) array per view), got a single "
            f"{object_points.shape} array; pass [points] * n_views if every view sees the same board"
        )
    if isinstance(image_points, np.ndarray) and image_points.ndim == 2:
        raise CalibrationError(
            "image_points must be a sequence of views (one (N, 2) array per view), got a single "
            f"{image_points.shape} array"
        )
    try:
        obj_list, img_list = list(object_points), list(image_points)
    except TypeError:
        raise CalibrationError("object_points and image_points must be sequences of per-view arrays") from None
    if len(obj_list) != len(img_list):
        raise CalibrationError(
            f"got {len(obj_list)} views of object points but {len(img_list)} views of image points; "
            "pass one object-point array per image (repeat the board's points for every view)"
        )
    n = len(img_list)
    if n < MIN_VIEWS:
        raise CalibrationError(
            f"only {n} view{'s' if n != 1 else ''}; Zhang's method needs at least {MIN_VIEWS} views "
            "of the board in different orientations. Collect more views (tilt the board)."
        )
    obj_out, img_out = [], []
    for i, (o, p) in enumerate(zip(obj_list, img_list)):
        o = _view_array(o, (2, 3), f"object points of view {i}")
        p = _view_array(p, (2,), f"image points of view {i}")
        if len(o) != len(p):
            raise CalibrationError(
                f"view {i} has {len(o)} object points but {len(p)} image points; every detected "
                "corner needs its board coordinate, in the same order"
            )
        if len(p) < MIN_POINTS_PER_VIEW:
            raise CalibrationError(
                f"view {i} has only {len(p)} points; a view needs at least {MIN_POINTS_PER_VIEW} "
                "(a plane-to-image homography has 8 degrees of freedom). Drop this view."
            )
        if o.shape[1] == 3:
            extent = float(np.ptp(o[:, :2], axis=0).max())
            if np.abs(o[:, 2]).max() > 1e-9 * max(extent, 1e-300):
                raise CalibrationError(
                    f"object points of view {i} are not planar with z = 0 (|z| up to "
                    f"{np.abs(o[:, 2]).max():.3g}); this calibration needs a planar target. Give "
                    "board coordinates (x, y, 0) or (N, 2) points in the board plane."
                )
            o = o[:, :2]
        extent = float(np.ptp(o, axis=0).max())
        if not OBJECT_EXTENT_RANGE[0] <= extent <= OBJECT_EXTENT_RANGE[1]:
            raise CalibrationError(
                f"the object points of view {i} span {extent:.3g} units; a calibration target spans "
                f"{OBJECT_EXTENT_RANGE[0]:g} to {OBJECT_EXTENT_RANGE[1]:g} of its unit (metres, millimetres, "
                "squares): give the board's coordinates in one such unit"
            )
        outside = ~np.all((p >= -IMAGE_SLACK * np.array([w, h])) & (p <= (1 + IMAGE_SLACK) * np.array([w, h])), axis=1)
        if outside.any():
            raise CalibrationError(
                f"{int(outside.sum())} image point(s) of view {i} lie far outside the {w}x{h} image (e.g. "
                f"{p[outside][0].tolist()}); image_size must be the (width, height) of the frames the corners "
                "were found in, and image points are pixels of those frames"
            )
        if _line_spread(o) < 1e-9:
            raise CalibrationError(
                f"the object points of view {i} are collinear (or all the same point); a planar "
                "target needs points spread in two directions"
            )
        thickness = _line_spread(p, absolute=True)
        if _line_spread(p) < 1e-3 or thickness < 0.25:
            raise CalibrationError(
                f"the image points of view {i} lie on a line (rms distance {thickness:.3g} px from "
                "it): the board was seen edge-on. Drop this view and tilt the board less."
            )
        img_out.append(p)
        obj_out.append(o)
    return obj_out, img_out, (w, h)


def _view_array(a, dims: tuple[int, ...], name: str) -> np.ndarray:
    return as_points(a, dims, name, error=CalibrationError)


def _line_spread(p: np.ndarray, absolute: bool = False) -> float:
    """How far (N, 2) points are from lying on one line.

    Relative: second / first singular value of the centred points (0 for a line).
    Absolute: rms distance of the points from their best-fit line.
    """
    c = p - p.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    if absolute:
        return float(s[1] / np.sqrt(len(p)))
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


# =========================================================================== entry point
def calibrate(object_points, image_points, image_size, *, model: str = "plumb_bob", skew: bool = False,
              fix_k3: bool = True, initial=None) -> CalibrationResult:
    """Calibrate a camera's intrinsics from views of a planar target.

    Parameters
    ----------
    object_points : sequence of V arrays, (N_i, 3) with z = 0 or (N_i, 2)
        Target coordinates in the target's plane, any unit (metres for the Duckietown
        board's :meth:`~dtscal_lib.boards.Board.object_points`).
    image_points : sequence of V arrays, (N_i, 2) or OpenCV's (N_i, 1, 2), pixels
    image_size : (width, height)
    model : ``"plumb_bob"`` (k1, k2, p1, p2 [, k3]) or ``"radial2"`` (k1, k2: Zhang's model)
    skew : also estimate the skew ``s = K[0, 1]`` (OpenCV cannot; ROS does not)
    fix_k3 : keep k3 = 0 as ROS does (``plumb_bob`` only)
    initial : optional ``(K, dist, rvecs, tvecs)`` to start the refinement from, one pose per
        view given (e.g. an earlier solution of the same views minus a few outliers, as
        :func:`dtscal_lib.pipeline.calibrate_without_outlier_views` does). It replaces the
        closed-form and multi-start search; the checks and the result are as without it.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    CalibrationError
        Degenerate or malformed input: fewer than 3 views, mismatched lengths, NaN,
        fewer than 4 or collinear points in a view, non-planar object points, all
        boards parallel, or an optimisation that does not reach a physical camera.
    """
    if model not in DIST_MODELS:
        raise CalibrationError(f"model must be one of {DIST_MODELS}, got {model!r}")
    if model == "radial2" and not fix_k3:
        raise CalibrationError("model 'radial2' estimates k1 and k2 only; use model='plumb_bob' to estimate k3")
    obj, img, size = _check_views(object_points, image_points, image_size)
    n_points = sum(len(p) for p in img)
    if n_points > MAX_POINTS:
        raise CalibrationError(
            f"{len(img)} views with {n_points} corners are more than one calibration takes ({MAX_POINTS}: about "
            f"{MAX_POINTS * 1.1e-6:.1f} GB of memory); calibrate a subset, e.g. one view in "
            f"{-(-n_points // MAX_POINTS)}")
    if model not in KIT_SOLVER_MODELS:
        if skew:
            raise CalibrationError(f"model {model!r} is calibrated by OpenCV, which cannot estimate the skew; "
                                   "drop --skew")
        return calibrate_opencv(obj, img, size, model)
    try:
        return _calibrate(obj, img, size, model, skew, fix_k3, initial)
    except MemoryError:
        raise CalibrationError(
            f"not enough memory to calibrate {len(img)} views ({n_points} corners, about {n_points * 1.1e-6:.2f} GB "
            "needed); calibrate fewer views or free memory") from None


def _calibrate(obj, img, size, model: str, skew: bool, fix_k3: bool, initial) -> CalibrationResult:
    dist_idx = _dist_indices(model, fix_k3)
    n_res = 2 * sum(len(p) for p in img)
    n_par = 4 + int(skew) + len(dist_idx) + 6 * len(img)
    if n_res <= n_par:
        raise CalibrationError(
            f"{n_res // 2} points in {len(img)} views cannot determine {n_par} parameters "
            f"({n_par - 6 * len(img)} intrinsic + 6 per view); add views or use views with more points"
        )
    Hs = [plane_homography(o, p) for o, p in zip(obj, img)]
    _check_not_degenerate(_constraint_matrix(Hs, size, skew), len(Hs), skew)

    problem = _Problem(obj, img, skew, dist_idx)
    if initial is None:
        theta, poses, iters = _refine_from_best_start(problem, Hs, obj, img, size, skew, dist_idx)
    else:
        theta, poses, iters = _refine(problem, *_initial_parameters(initial, len(obj), skew, dist_idx))
    theta, poses, iters = _reseed_trapped_poses(problem, theta, poses, iters)

    K, dist = _unpack(theta, skew, dist_idx)
    try:
        as_K(K)
    except ValueError:
        raise CalibrationError(
            f"the optimisation did not reach a physical camera (K = {K.tolist()}); the views are "
            "probably too few or too similar. Add views with the board tilted and in the image corners."
        ) from None
    _check_tilt_spread(poses[:, :3])
    try:
        res = problem.residuals_stacked(theta, poses)
        sigma2, cov, cov_noise, method = _intrinsic_covariance(problem, theta, poses)
    except (np.linalg.LinAlgError, DtscalError) as exc:
        raise CalibrationError(
            f"the calibration did not converge to a usable camera ({exc}); add views with the board "
            "tilted in different directions and covering the image"
        ) from None
    sq = np.add.reduceat((res ** 2).sum(axis=1), problem.starts)
    npts = problem.counts
    if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(cov_noise))) or np.any(np.diag(cov_noise) < 0):
        raise CalibrationError("the parameter covariance is singular: the views do not determine the camera; add views")
    names = _param_names(skew, dist_idx)
    std = {n: float(np.sqrt(v)) for n, v in zip(names, np.diag(cov))}
    std_noise = {n: float(np.sqrt(v)) for n, v in zip(names, np.diag(cov_noise))}
    # whether the views determine the focal length is a question about the poses, not about
    # how well the model fits: the noise model's deviation answers it
    worst = max(std_noise["fx"] / K[0, 0], std_noise["fy"] / K[1, 1])
    if worst > MAX_RELATIVE_FOCAL_STD:
        raise CalibrationError(
            f"the views do not determine the focal length (standard deviation {100 * worst:.0f}% of it, "
            f"residual sigma {np.sqrt(sigma2):.2g} px); the corners are too noisy for these poses. Add "
            "views with the board tilted 20-45 degrees in different directions and filling the image."
        )
    return CalibrationResult(
        K=K,
        dist=dist,
        rms=float(np.sqrt(sq.sum() / npts.sum())),
        per_view_rms=np.sqrt(sq / npts),
        rvecs=poses[:, :3].copy(),
        tvecs=poses[:, 3:].copy(),
        std=std,
        model=model,
        skew=bool(skew),
        image_size=size,
        n_views=len(obj),
        n_points=int(npts.sum()),
        sigma=float(np.sqrt(sigma2)),
        iterations=iters,
        converged=not problem.capped,
        object_points=obj,
        image_points=img,
        std_noise_model=std_noise,
        std_method=method,
        covariance=cov,
    )


#: a view whose RMS exceeds this many times the median view's gets its pose re-estimated (PnP)
_TRAPPED_VIEW_FACTOR = 3.0


def _reseed_trapped_poses(problem: "_Problem", theta, poses, iters: int, rounds: int = 2):
    """Re-estimate the pose of views that fit far worse than the rest, and refine again if that helps.

    A planar board seen nearly face-on has two poses that project almost alike (the tilt flipped);
    started from a poor camera, one view's pose can end up in the wrong one and stay there: on the
    recorded session with ``radial2`` and skew, one view kept 2.9 px RMS (the others 0.1 px) while
    ``cv2.solvePnP`` with the refined camera fits it to 0.07 px. For each view above
    :data:`_TRAPPED_VIEW_FACTOR` x the median view's RMS, PnP with the current camera proposes a pose;
    when it fits that view better than half as badly, the refinement continues from there. A view
    that is bad in itself (a blurred detection) keeps its pose: PnP cannot fit it better.
    """
    K, dist = _unpack(theta, problem.skew, problem.dist_idx)
    for _ in range(rounds):
        r = problem.residuals_stacked(theta, poses)
        pv = np.sqrt(np.add.reduceat((r ** 2).sum(axis=1), problem.starts) / problem.counts)
        suspects = np.flatnonzero(pv > _TRAPPED_VIEW_FACTOR * np.median(pv))
        if not len(suspects):
            break
        new = poses.copy()
        for v in suspects:
            o3, m = problem.obj3[v], np.asarray(problem.img[v], dtype=np.float64).reshape(-1, 2)
            try:
                ok, rv, tv = cv2.solvePnP(o3, m.reshape(-1, 1, 2), K, dist)
            except cv2.error:
                continue
            if not ok:
                continue
            e = np.sqrt(((project_points(o3, rv.ravel(), tv.ravel(), K, dist) - m) ** 2).sum(axis=1).mean())
            if np.isfinite(e) and e < 0.5 * pv[v]:
                new[v] = np.concatenate([rv.ravel(), tv.ravel()])
        if np.array_equal(new, poses):
            break
        t2, p2, more = _refine(problem, theta, new)
        if _cost(problem.residuals_stacked(t2, p2)) >= _cost(problem.residuals_stacked(theta, poses)):
            break
        theta, poses, iters = t2, p2, iters + more
        K, dist = _unpack(theta, problem.skew, problem.dist_idx)
    return theta, poses, iters


def _initial_parameters(initial, n_views: int, skew: bool, dist_idx) -> tuple[np.ndarray, np.ndarray]:
    """``theta, poses`` from a given start ``(K, dist, rvecs, tvecs)`` (see :func:`calibrate`)."""
    try:
        K, dist, rvecs, tvecs = initial
        K = np.asarray(K, dtype=np.float64).reshape(3, 3)
        dist = np.zeros(5) if dist is None else np.resize(np.asarray(dist, dtype=np.float64).ravel(), 5)
        poses = np.hstack([np.asarray(rvecs, dtype=np.float64).reshape(-1, 3),
                           np.asarray(tvecs, dtype=np.float64).reshape(-1, 3)])
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"initial must be (K, dist, rvecs, tvecs), one pose per view ({exc})") from None
    if len(poses) != n_views or not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist))
                                     and np.all(np.isfinite(poses))) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError(f"initial must be a finite camera with positive focal lengths and {n_views} poses")
    theta = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], [K[0, 1]] if skew else [],
                            dist[list(dist_idx)]])
    return theta, poses


#: iterations each starting point gets before the better one is refined to convergence
_START_TRIAL_ITERATIONS = 8
#: the closed form is trusted alone when its focal lengths are within this fraction of OpenCV's start
_START_AGREEMENT = 0.25


def _focal_disagreement(K_a: np.ndarray, K_b: np.ndarray) -> float:
    """Largest relative difference of the two starts' focal lengths."""
    return float(max(abs(K_a[i, i] - K_b[i, i]) / max(K_a[i, i], K_b[i, i]) for i in (0, 1)))


def _refine_from_best_start(problem: "_Problem", Hs, obj, img, size, skew: bool, dist_idx):
    """Refine from the better of two starts: Zhang's closed form and OpenCV's own.

    Zhang's closed form ignores the lens. Under strong distortion, with views that are close to
    fronto-parallel, it can start the focal length far from the truth (100 px for 307 px on the
    first 40 samples of the recorded session), and the refinement from there ends in a local
    minimum (RMS 0.59 px instead of 0.064 px) after a hundred slow iterations. OpenCV's start
    (principal point at the centre, focal lengths from vanishing points) is cruder but not
    misled that way. When the two starts disagree on the focal length by more than
    :data:`_START_AGREEMENT`, each gets a few iterations and the one with the lower cost goes on to
    convergence; otherwise the closed form is the start, as it always was.
    """
    starts = []
    K_zhang = zhang_closed_form(Hs, size, skew=skew)
    if K_zhang is not None and _plausible(K_zhang, size):
        starts.append(K_zhang)
    try:
        starts.append(_opencv_initial_K(obj, img, size))
    except CalibrationError:
        if not starts:
            raise
    if len(starts) == 2 and _focal_disagreement(*starts) <= _START_AGREEMENT:
        starts = starts[:1]  # the usual case: the closed form is where OpenCV's start points, so use it alone
    trials = []
    for K0 in starts:
        theta0 = np.concatenate([[K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2]], [K0[0, 1]] if skew else [],
                                 np.zeros(len(dist_idx))])
        poses0 = np.array([np.concatenate(_pose_from_homography(H, K0)) for H in Hs])
        if len(starts) == 1:
            return _refine(problem, theta0, poses0)
        try:
            theta, poses, it = _refine(problem, theta0, poses0, max_iter=_START_TRIAL_ITERATIONS)
            cost = _cost(problem.residuals_stacked(theta, poses))
        except cv2.error:
            continue
        if np.isfinite(cost):
            trials.append((cost, theta, poses, it))
    if not trials:
        raise CalibrationError("no starting camera led anywhere from these views; add views with tilted boards")
    _, theta, poses, it = min(trials, key=lambda trial: trial[0])
    theta, poses, more = _refine(problem, theta, poses)
    return theta, poses, it + more


def _check_tilt_spread(rvecs) -> None:
    spread = board_normal_spread(rvecs)
    if spread < MIN_TILT_SPREAD_DEG:
        raise CalibrationError(
            f"the {len(rvecs)} boards are (nearly) parallel: every board normal is within {spread:.1f} degrees "
            f"of their mean direction (at least {MIN_TILT_SPREAD_DEG:g} needed), and parallel views do not "
            "determine the focal length and principal point. Tilt the board left/right and up/down by "
            "20-45 degrees."
        )


def _plausible(K: np.ndarray, size: tuple[int, int]) -> bool:
    w, h = size
    fx, fy = K[0, 0], K[1, 1]
    return bool(
        0 < fx < 100 * (w + h) and 0 < fy < 100 * (w + h) and 0.2 < fx / fy < 5
        and -w < K[0, 2] < 2 * w and -h < K[1, 2] < 2 * h and abs(K[0, 1]) < 0.5 * fx
    )


def _opencv_initial_K(obj, img, size) -> np.ndarray:
    """OpenCV's own starting point (principal point at the centre, focal lengths from vanishing points)."""
    o32 = [np.column_stack([o, np.zeros(len(o))]).astype(np.float32) for o in obj]
    i32 = [p.astype(np.float32).reshape(-1, 1, 2) for p in img]
    K = np.asarray(cv2.initCameraMatrix2D(o32, i32, size), dtype=np.float64)
    if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0):
        raise CalibrationError("could not find a starting camera matrix from these views; add views with tilted boards")
    return K
