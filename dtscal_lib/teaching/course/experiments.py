"""Experiments the student runs and changes (issue 24): each returns numbers the notebook prints and a
predict-then-check question compares (:mod:`dtscal_lib.teaching.selfcheck.predict`).

* :func:`span_at_yaw` - where the board lands in the image when the camera turns (notebook 01);
* :func:`invariance_experiment` - normalization as invariance to the choice of origin and scale, error
  against the TRUE homography (notebook 02, Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., sec. 4.4.4);
* :func:`off_plane_experiment` - points lifted off the plane break a homography (notebook 02);
* :func:`degenerate_views` - the rank of Zhang's V for tilted, parallel and fronto-parallel boards (notebook 03);
* :func:`field_of_view`, :func:`line_bend_px`, :func:`lens_explorer` - the lens's view, k1/k2 that straighten
  lines (notebook 04);
* :func:`camera_height_pitch`, :func:`pixel_footprint_mm`, :func:`yaw_cost_mm` - what the ground homography says
  about the camera and what a misplaced robot costs (notebook 05).
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from ... import camera as cam
from ...boards import DUCKIETOWN_BOARD, Board
from ...duckietown import IMAGE_SIZE
from ...homography import apply_homography
from .figure import new_figure, png_bytes
from .homography import unnormalized_dlt
from .projection import look_at_pose

__all__ = ["span_at_yaw", "invariance_experiment", "invariance_table", "dlt_column_range", "off_plane_experiment",
           "lift_shift_px", "pitch_cost_mm", "degenerate_views", "zhang_constraints", "sigma_trials", "field_of_view",
           "corner_shift_px", "fixed_point_converged",
           "line_bend_px", "mystery_lens", "lens_explorer", "camera_height_pitch", "pixel_footprint_mm",
           "yaw_cost_mm",
           "lane_markings_on_ground"]


# --------------------------------------------------------------------------------------------- notebook 01
def span_at_yaw(project: Callable, K, yaw_deg: float, distance: float = 0.45,
                board: Board = DUCKIETOWN_BOARD) -> tuple[float, float]:
    """Leftmost and rightmost u (pixels) of the board's corners for a camera turned by ``yaw_deg``.

    :func:`look_at_pose` keeps the board's centre on the optical axis, so turning the camera only
    foreshortens the board: it never leaves the image.
    """
    R, t = look_at_pose(yaw_deg=yaw_deg, distance=distance, board=board)
    uv = np.asarray(project(K, R, t, board.object_points()), dtype=float)
    return float(uv[:, 0].min()), float(uv[:, 0].max())


# --------------------------------------------------------------------------------------------- notebook 02
_H_TRUE = np.array([[0.9, 0.12, 40.0], [-0.05, 1.1, 25.0], [2e-4, 4e-4, 1.0]])


def invariance_experiment(estimate: Callable, changes: Sequence[tuple[float, float]], sigma: float = 1.0,
                          n_points: int = 35, seed: int = 3) -> list[dict]:
    """Fit the same noisy correspondences in different source coordinates; error against the TRUTH.

    The source points (spread over a 640 x 480 image) are re-expressed as ``scale * p + offset`` for each
    ``(offset, scale)`` in ``changes`` - the same points, only another origin and unit - and fitted by
    ``estimate`` (the normalized DLT) and by the DLT without normalization. Each fit is mapped back to the
    original coordinates and compared with the true homography on a grid over the image (RMS pixels).

    A normalized DLT gives the same answer whatever the coordinates (its error column is constant); the
    unnormalized one gives a different answer for each choice, which is Hartley's reason to normalize:
    an estimate should not depend on where you put the origin.
    """
    rng = np.random.default_rng(seed)
    src = np.column_stack([rng.uniform(0, 640, n_points), rng.uniform(0, 480, n_points)])
    dst = apply_homography(_H_TRUE, src) + rng.normal(0.0, sigma, size=(n_points, 2))
    gu, gv = np.meshgrid(np.linspace(0, 640, 9), np.linspace(0, 480, 7))
    grid = np.column_stack([gu.ravel(), gv.ravel()])
    truth = apply_homography(_H_TRUE, grid)
    rows = []
    for offset, scale in changes:
        T = np.array([[scale, 0.0, offset], [0.0, scale, offset], [0.0, 0.0, 1.0]])
        moved = src * scale + offset
        row = {"offset": float(offset), "scale": float(scale)}
        for key, fit in (("normalized", estimate), ("unnormalized", unnormalized_dlt)):
            H = np.asarray(fit(moved, dst), dtype=float) @ T  # back to the original coordinates
            err = apply_homography(H, grid) - truth
            row[key] = float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))
        rows.append(row)
    return rows


def invariance_table(rows: list[dict]) -> str:
    """The rows of :func:`invariance_experiment` as a table (2 decimals: round-off never shows)."""
    lines = ["source coordinates      error against the truth (RMS px)",
             "  offset     scale      normalized   unnormalized"]
    for r in rows:
        lines.append(f"  {r['offset']:6g}  {r['scale']:8g}  {r['normalized']:12.2f}  {r['unnormalized']:13.2f}")
    return "\n".join(lines)


def off_plane_experiment(heights_m: Sequence[float], K=None, board: Board = DUCKIETOWN_BOARD,
                         yaw_deg: float = 30.0, pitch_deg: float = -20.0, distance: float = 0.4) -> list[float]:
    """RMS transfer error (px) of the best homography when every other corner is lifted by ``h`` metres.

    A homography maps one plane to the image; corners off that plane (a board that is not flat, a box
    on the floor) cannot all be fitted, and the fit residual grows with their height. Exact pixels:
    every residual is the model's failure, not noise.
    """
    import cv2

    K = cam.as_K(np.array([[307.7, 0, 329.7], [0, 315.0, 244.5], [0, 0, 1]]) if K is None else K)
    R, t = look_at_pose(yaw_deg=yaw_deg, pitch_deg=pitch_deg, distance=distance, board=board)
    X = board.object_points().copy()
    out = []
    for h in heights_m:
        lifted = X.copy()
        lifted[::2, 2] = -h  # every other corner raised towards the camera side
        uv = cam.project_points(lifted, R, t, K)
        H = cv2.findHomography(X[:, :2], uv, 0)[0]
        err = apply_homography(H, X[:, :2]) - uv
        out.append(float(np.sqrt(np.mean(np.sum(err ** 2, axis=1)))))
    return out


def lift_shift_px(h: float, K=None, board: Board = DUCKIETOWN_BOARD, yaw_deg: float = 30.0, pitch_deg: float = -20.0,
                  distance: float = 0.4) -> tuple[float, float]:
    """Smallest and largest pixel shift of the corners :func:`off_plane_experiment` lifts by ``h`` metres.

    In that pose (0.4 m, turned 30 deg and 20 deg) the camera sees the lift obliquely, so a corner moves by less
    than f h / Z; these are the numbers the prediction's explanation quotes.
    """
    K = cam.as_K(np.array([[307.7, 0, 329.7], [0, 315.0, 244.5], [0, 0, 1]]) if K is None else K)
    R, t = look_at_pose(yaw_deg=yaw_deg, pitch_deg=pitch_deg, distance=distance, board=board)
    X = board.object_points().copy()
    lifted = X.copy()
    lifted[::2, 2] = -h
    moved = np.linalg.norm(cam.project_points(lifted, R, t, K) - cam.project_points(X, R, t, K), axis=1)[::2]
    return float(moved.min()), float(moved.max())


def dlt_column_range(offset: float, n_points: int = 35, seed: int = 2) -> tuple[float, float]:
    """Smallest and largest column scale (max |entry|) of the unnormalized DLT's matrix A for source points
    spread over a 640 x 480 image and shifted by ``offset`` (destination: pixels of a homography)."""
    rng = np.random.default_rng(seed)
    src = np.column_stack([rng.uniform(0, 640, n_points), rng.uniform(0, 480, n_points)]) + offset
    dst = apply_homography(_H_TRUE, src - offset)
    x, y, u, v = src[:, 0], src[:, 1], dst[:, 0], dst[:, 1]
    one, zero = np.ones(n_points), np.zeros(n_points)
    A = np.vstack([np.column_stack([-x, -y, -one, zero, zero, zero, u * x, u * y, u]),
                   np.column_stack([zero, zero, zero, -x, -y, -one, v * x, v * y, v])])
    scales = np.abs(A).max(axis=0)
    return float(scales.min()), float(scales.max())


# --------------------------------------------------------------------------------------------- notebook 03
def sigma_trials(views, n_views: int = 8, trials: int = 12, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Calibrate ``trials`` random subsets of ``n_views`` views; the errors against the truth and the reported sigmas.

    Each subset gets the kit's full calibration (``plumb_bob``); returned are the errors of fx, fy, cx, cy against
    ``views.K_true`` and the standard deviations the calibration reports for them (``result.std``), both
    (trials, 4). If the sigmas are honest, about 68 % of the errors lie within 1 sigma and 95 % within 2.
    """
    from ...calibration import calibrate

    if not 3 <= n_views <= views.n_views:
        raise ValueError(f"n_views must be 3 to {views.n_views} (the views there are), got {n_views}")
    rng = np.random.default_rng(seed)
    K = np.asarray(views.K_true, dtype=float)
    errors, sigmas = [], []
    for _ in range(int(trials)):
        pick = rng.choice(views.n_views, int(n_views), replace=False)
        r = calibrate([views.object_points[i] for i in pick], [views.image_points[i] for i in pick], views.size,
                      model="plumb_bob")
        errors.append([r.K[0, 0] - K[0, 0], r.K[1, 1] - K[1, 1], r.K[0, 2] - K[0, 2], r.K[1, 2] - K[1, 2]])
        sigmas.append([r.std[k] for k in ("fx", "fy", "cx", "cy")])
    return np.array(errors), np.array(sigmas)


def _rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    a, b = math.radians(yaw_deg), math.radians(pitch_deg)
    Ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    return Ry @ Rx


def degenerate_views(constraints: Callable, K, kind: str, n_views: int = 10) -> dict:
    """Zhang's V for an exact view set of one ``kind``; its rank says how many intrinsics the views fix.

    ``kind``: ``"tilted"`` (``n_views`` boards tilted 20-40 degrees in different directions), ``"parallel"``
    (one tilted orientation, only moved around) or ``"fronto"`` (every board facing the camera squarely).
    Returns ``rank`` (singular values above 1e-9 of the largest), ``unknowns`` (5) and the relative singular
    values ``sv``. ``constraints`` is ``intrinsic_constraints`` (the student's or a stand-in).
    """
    K = cam.as_K(K)
    rng = np.random.default_rng(7)
    Hs = []
    for i in range(n_views):
        if kind == "tilted":
            ang = 2 * math.pi * i / n_views
            tilt = 20 + 20 * (i % 3) / 2
            R = _rotation(tilt * math.cos(ang), tilt * math.sin(ang))
        elif kind == "parallel":
            R = _rotation(25.0, -15.0)
        elif kind == "fronto":
            R = np.eye(3)
        else:
            raise ValueError(f"kind must be 'tilted', 'parallel' or 'fronto', not {kind!r}")
        t = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.08, 0.08), rng.uniform(0.35, 0.7)])
        H = K @ np.column_stack([R[:, 0], R[:, 1], t])
        Hs.append(H / np.linalg.norm(H))
    V = np.vstack([np.asarray(constraints(H), dtype=float) for H in Hs])
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    sv = np.linalg.svd(V, compute_uv=False)
    rel = sv / sv[0]
    return {"kind": kind, "n_views": n_views, "rank": int(np.sum(rel > 1e-9)), "unknowns": 5, "sv": rel, "V": V}


def zhang_constraints(H) -> np.ndarray:
    """The two rows v12 and v11 - v22 of eqs. (12)-(13) for one homography (the notebook's stand-in)."""
    from ...calibration import _v_row

    H = np.asarray(H, dtype=float)
    return np.stack([_v_row(H, 0, 1), _v_row(H, 0, 0) - _v_row(H, 1, 1)])


# --------------------------------------------------------------------------------------------- notebook 04
def field_of_view(K, dist, size: tuple[int, int] = IMAGE_SIZE) -> tuple[float, float]:
    """Horizontal and diagonal field of view (degrees) of a lens: the angle between the rays of opposite
    image edges (or corners), through the lens model (not the pinhole ``2 atan(w / 2f)``)."""
    K = cam.as_K(K)
    w, h = size
    cy = K[1, 2]
    pix = np.array([[0.0, cy], [w - 1.0, cy], [0.0, 0.0], [w - 1.0, h - 1.0]])
    xy = cam.undistort_normalized(cam.pixel_to_normalized(pix, K), dist)
    rays = np.column_stack([xy, np.ones(len(xy))])
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)

    def angle(a, b):
        return math.degrees(math.acos(float(np.clip(rays[a] @ rays[b], -1, 1))))

    return angle(0, 1), angle(2, 3)


def corner_shift_px(K, dist, size: tuple[int, int] = IMAGE_SIZE) -> float:
    """How far (pixels) the lens moves the point a pinhole camera would see at an image corner (the largest of 4)."""
    K = cam.as_K(K)
    w, h = size
    pin = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
    moved = cam.normalized_to_pixel(cam.distort_normalized(cam.pixel_to_normalized(pin, K), dist), K)
    return float(np.linalg.norm(moved - pin, axis=1).max())


def fixed_point_converged(K, dist, rounds: int, size: tuple[int, int] = IMAGE_SIZE, tol_px: float = 0.01) -> int:
    """How many of the 4 image corners OpenCV's fixed-point undistortion brings within ``tol_px`` of the truth
    after ``rounds`` rounds (``cv2.undistortPointsIter``): each corner is undistorted, then distorted again with
    the exact model, and compared with where it started."""
    import cv2

    K = cam.as_K(K)
    d = np.asarray(cam.as_dist(dist), dtype=float)
    w, h = size
    corners = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
    crit = (cv2.TERM_CRITERIA_COUNT, int(rounds), 0.0)
    xy = cv2.undistortPointsIter(corners.reshape(-1, 1, 2), K, d, None, None, crit).reshape(-1, 2)
    back = cam.normalized_to_pixel(cam.distort_normalized(xy, d), K)
    return int(np.sum(np.linalg.norm(back - corners, axis=1) < tol_px))


def line_bend_px(K, dist, k1: float, k2: float, size: tuple[int, int] = IMAGE_SIZE, step: int = 2) -> float:
    """How far (pixels) straight lines still bend in the picture the lens explorer shows for a guess ``k1, k2``.

    The picture is the explorer's: the true lens ``dist`` records a grid of straight lines, and the recording is
    rectified with the guess (``dist`` with ``k1, k2`` replaced), so picture pixel ``x`` shows what the lens
    recorded at ``K distort_guess(K^-1 x)``, which is the pinhole image's point ``K undistort_true(...)`` of it.
    Each straight line of the pinhole image (7 rows, 9 columns) is followed through the picture where it is drawn
    (every column, or row, of pixels where the line crosses it; ``step`` px apart), a straight line is fitted to
    those points; the result is the RMS distance of a line's points from its fit, averaged over the lines. So the
    number measures what the picture shows: 0 for the true lens (the lines are straight), and a guess that folds the
    picture near its edges (a line drawn twice) scores badly because the picture is bad there, never because of a
    point outside it (issue 29: the old number jumped to 600-800 px on roots the picture never showed).
    """
    K = cam.as_K(K)
    d = np.asarray(cam.as_dist(dist), dtype=float).copy()
    guess = d.copy()
    guess[0], guess[1] = k1, k2
    w, h = size
    u, v = np.meshgrid(np.arange(0, w, step, dtype=float), np.arange(0, h, step, dtype=float))
    src = cam.normalized_to_pixel(cam.distort_normalized(cam.pixel_to_normalized(
        np.column_stack([u.ravel(), v.ravel()]), K), guess), K)
    seen = (src[:, 0] >= 0) & (src[:, 0] <= w - 1) & (src[:, 1] >= 0) & (src[:, 1] <= h - 1)
    ideal = np.full_like(src, np.nan)
    ideal[seen] = cam.normalized_to_pixel(cam.undistort_normalized(cam.pixel_to_normalized(src[seen], K), d), K)
    iu, iv = ideal[:, 0].reshape(u.shape), ideal[:, 1].reshape(u.shape)
    bends = []
    for c, along, other, axis in ([(c, iv, iu, 0) for c in np.linspace(0.06, 0.94, 7) * h]
                                  + [(c, iu, iv, 1) for c in np.linspace(0.06, 0.94, 9) * w]):
        f = (along - c) if axis == 0 else (along - c).T  # rows of f run along the picture's v (axis 0) or u
        o = other if axis == 0 else other.T
        a, b = f[:-1], f[1:]
        cross = (a * b <= 0) & np.isfinite(a) & np.isfinite(b) & (a != b)
        cross &= np.isfinite(o[:-1]) & (np.abs(o[:-1] - (w if axis == 0 else h) / 2) <= 0.47 * (w if axis == 0 else h))
        k, col = np.nonzero(cross)
        if len(k) < 3:
            continue
        frac = a[k, col] / (a[k, col] - b[k, col])
        pos = (k + frac) * step  # where the line crosses, along the scanned axis
        pts = np.column_stack([col * step, pos]) if axis == 0 else np.column_stack([pos, col * step])
        centred = pts - pts.mean(axis=0)
        normal = np.linalg.svd(centred, full_matrices=False)[2][-1]
        bends.append(float(np.sqrt(np.mean((centred @ normal) ** 2))))
    return float(np.mean(bends)) if bends else 0.0


def mystery_lens() -> np.ndarray:
    """The lens of notebook 04's straighten-the-lines game: ``(k1, k2, p1, p2, k3)``, printed nowhere in the notebook.

    A wide lens of the Duckiebot's kind (barrel, k1 < 0 and a small positive k2; Duckietown's per-robot files have k1
    around -0.27), made up for the game and not the recorded camera's, whose coefficients the notebook prints at its
    top: the student finds it by making the lines straight, not by reading it off.
    """
    return np.array([-0.21, 0.03, 0.0, 0.0, 0.0])


def lens_explorer(K, dist, size: tuple[int, int] = IMAGE_SIZE, *, k1: float = 0.0, k2: float = 0.0):
    """Sliders for k1 and k2: a grid of straight lines seen through the true lens, undone with the sliders'
    guess, redrawn live; the line under it gives the remaining bend (:func:`line_bend_px`). The sliders start at
    ``k1, k2`` (the notebook passes the student's own guess).

    Its text form (what a static page and nbval see) is one fixed sentence, so the stored output is the
    same on every machine.
    """
    import ipywidgets as widgets

    from .distortion import distort_image, grid_image

    K = cam.as_K(K)
    dist = cam.as_dist(dist)
    bent = distort_image(grid_image(size, spacing=40), K, dist)

    class LensBox(widgets.VBox):
        def __repr__(self) -> str:
            return ("lens explorer: sliders for k1 and k2 undo a wide lens on a grid of straight lines "
                    "(needs a running Jupyter kernel)")

    fs = dict(continuous_update=False, style={"description_width": "40px"}, layout=widgets.Layout(width="360px"))
    start_k1, start_k2 = float(k1), float(k2)
    k1 = widgets.FloatSlider(value=start_k1, min=-0.5, max=0.2, step=0.01, description="k1", readout_format=".2f", **fs)
    k2 = widgets.FloatSlider(value=start_k2, min=-0.1, max=0.2, step=0.005, description="k2", readout_format=".3f",
                             **fs)
    image = widgets.Image(format="png", layout=widgets.Layout(width="420px", height="315px"))
    status = widgets.HTML()

    def redraw(_change=None):
        guess = np.asarray(dist, dtype=float).copy()
        guess[0], guess[1] = k1.value, k2.value
        maps = cam.rectification_maps(K, guess, K, size)
        undone = cam.rectify_image(bent, maps)
        fig = new_figure(4.2, 3.15, dpi=100)
        ax = fig.add_subplot()
        ax.imshow(undone, cmap="gray", vmin=0, vmax=255)
        ax.set_title(f"undone with k1 = {k1.value:.2f}, k2 = {k2.value:.3f}", fontsize=9)
        ax.axis("off")
        image.value = png_bytes(fig)
        status.value = f"<b>lines still bend by {line_bend_px(K, dist, k1.value, k2.value):.2f} px (RMS)</b>"

    k1.observe(redraw, names="value")
    k2.observe(redraw, names="value")
    redraw()
    return LensBox([k1, k2, image, status])


# --------------------------------------------------------------------------------------------- notebook 05
def camera_height_pitch(H_ground, K) -> tuple[float, float]:
    """Camera height (metres above the ground) and pitch (degrees below the horizon) from the ground homography.

    ``H_ground`` maps rectified pixels to ground metres (Duckietown's convention), so its inverse maps the
    ground point ``(x, y, 1)`` to pixels: ``H^-1 = lambda K [r1 r2 t]`` with ``r1, r2`` the ground's x and y
    axes seen from the camera and ``t`` the ground origin in the camera frame (eqs. (5)-(6) with the ground
    as the plane). The camera centre in the ground frame is ``C = -R^T t`` (its height is ``C_z``) and the
    pitch is how far the optical axis (third row of ``R``) points below the horizontal. The kit's
    :func:`dtscal_lib.ground.camera_pose_from_homography` does the work.
    """
    from ...ground import camera_pose_from_homography

    pose = camera_pose_from_homography(H_ground, np.asarray(K, dtype=float)[:3, :3])
    return pose["height_m"], pose["pitch_down_deg"]


def pixel_footprint_mm(H_ground, x_ahead: float, u: float = 320.0) -> float:
    """Ground length (mm) that one rectified pixel row spans at ``x_ahead`` metres in front of the robot."""
    H = np.asarray(H_ground, dtype=float)
    vs = np.arange(0.0, 480.0, 0.25)
    g = apply_homography(H, np.column_stack([np.full_like(vs, u), vs]))
    ok = g[:, 0] > 0
    v = float(np.interp(x_ahead, g[ok, 0][::-1], vs[ok][::-1]))
    a, b = apply_homography(H, np.array([[u, v], [u, v + 1.0]]))
    return 1000.0 * float(np.linalg.norm(a - b))


def yaw_cost_mm(yaw_deg: float, x_ahead: float) -> float:
    """Sideways error (mm) at ``x_ahead`` metres when the robot stood turned by ``yaw_deg`` on the board.

    The calibration then believes the board's axes are the robot's: every ground point is rotated by the
    yaw about the robot's origin, so a point ``x`` ahead lands ``x sin(yaw)`` to the side.
    """
    return 1000.0 * x_ahead * math.sin(math.radians(yaw_deg))


def pitch_cost_mm(pitch_error_deg: float, x_ahead: float, height: float) -> float:
    """Error (mm, along x) of the ground point ``x_ahead`` metres ahead when the calibration's pitch is off.

    A camera ``height`` metres up sees the point at ``atan(height / x)`` below the horizon; a calibration that
    believes the camera looks ``pitch_error_deg`` less steeply than it does puts the same pixel's ray that much
    flatter, at ``height / tan(atan(height / x) - error)``. The ray flattens towards the horizon far away, so
    the error grows fast with distance (and a ray at or above the horizon never meets the ground: inf).
    """
    angle = math.atan2(height, x_ahead) - math.radians(pitch_error_deg)
    if angle <= 0:
        return math.inf
    return 1000.0 * (height / math.tan(angle) - x_ahead)


def lane_markings_on_ground(image, H_ground, *, v_min: int = 250, x_max: float = 0.6) -> dict:
    """The lane markings of a frame (yellow centre line on the left, white line on the right) mapped to the
    ground with ``H_ground``; each fitted by a straight line ``y = a + b x``.

    Marking pixels are picked by colour (HSV: yellow hue 15-40 saturated and bright; white unsaturated and
    bright) below image row ``v_min`` (the road, not the wall), and kept only off the calibration sheet
    (|y| > 0.16 m, on their side of the robot) and within ``x_max`` metres ahead. Returns, per marking,
    ``n`` (points), ``angle_deg`` (direction against the robot's x axis, left positive), ``offset_m``
    (y at x = 0) and ``x_range``. Parallel markings have equal angles: a right calibration maps the road's
    parallel lines to parallel lines.
    """
    import cv2

    from ...ground import pixel_to_ground

    hsv = cv2.cvtColor(np.asarray(image), cv2.COLOR_BGR2HSV)
    hue, sat, val = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    vv, uu = np.mgrid[0:hsv.shape[0], 0:hsv.shape[1]]
    out = {}
    for name, mask, side in (("yellow", (hue > 15) & (hue < 40) & (sat > 120) & (val > 120), 1.0),
                             ("white", (sat < 40) & (val > 170), -1.0)):
        sel = mask & (vv > v_min)
        g = pixel_to_ground(H_ground, np.column_stack([uu[sel], vv[sel]]).astype(float))
        g = g[(side * g[:, 1] > 0.16) & (g[:, 0] > 0) & (g[:, 0] < x_max)]
        if len(g) < 10:
            continue
        b, a = np.polyfit(g[:, 0], g[:, 1], 1)
        out[name] = {"n": int(len(g)), "angle_deg": float(np.degrees(np.arctan(b))), "offset_m": float(a),
                     "x_range": (float(g[:, 0].min()), float(g[:, 0].max()))}
    return out
