"""How good is a calibration: a verdict with reasons, and the projection uncertainty over the image.

A small RMS does not make a calibration good (the lesson of mrcal's documentation): a model that
cannot follow the lens, or corners that the detector put in the wrong place in the same way view
after view, can fit with a modest RMS and still move every pixel by more than the reported standard
deviations admit. So :func:`assess` judges a :class:`~dtscal_lib.calibration.CalibrationResult` by

1. **its residuals against the corner noise of these very images.** The noise model: every detected
   corner coordinate is the true one plus independent zero-mean Gaussian noise of one standard
   deviation ``sigma_noise`` (pixels, per coordinate), the same for every corner. ``sigma_noise`` is
   measured without any camera model (:func:`corner_noise`): on a smooth image of a regular grid
   every interior corner is predicted by the least-squares quadratic through its 8 grid neighbours
   (perspective and lens distortion are smooth; on the symmetric ring the odd third-order terms
   cancel, so only fourth-order curvature is left, far below the noise), and the robust spread of
   those predictions' errors, divided by the prediction's own noise gain, is ``sigma_noise``. A fit
   whose residual ``sigma`` is near ``sigma_noise`` explains the data; a fit several times worse has
   something the model cannot absorb.
2. **residuals that are systematic, not noise**: views whose own RMS is far above the others (named);
   a column or row of corners offset the same way in many views (named with its views: a detector
   pulled by the board's edge does this); a radial pattern the distortion model cannot absorb;
   neighbouring corners that share one error.
3. **the data**: too few views, boards all nearly parallel.
4. **the projection uncertainty** (:func:`projection_uncertainty`, mrcal's uncertainty maps): how far
   the projection of a fixed 3-D point moves, 1 sigma, when the parameters move within their
   covariance.

The verdict is the worst severity of the findings: ``"good"`` when there is none, else
``"doubtful"`` or ``"bad"``; every finding carries advice (which views to drop, where to hold the
board next).

Example: eight well-tilted views, but every board in the middle of the image, so the image corners
are extrapolated and the verdict says where to hold the board next.

>>> import numpy as np
>>> from dtscal_lib import camera, duckietown as dt
>>> from dtscal_lib.boards import DUCKIETOWN_BOARD
>>> from dtscal_lib.calibration import calibrate
>>> rng = np.random.default_rng(1)
>>> obj = DUCKIETOWN_BOARD.object_points()
>>> poses = [([a, b, 0.1 * k], [-0.1 + 0.03 * a, -0.06, 0.3 + 0.02 * k])
...          for k, (a, b) in enumerate([(0.4, 0.1), (-0.4, 0.2), (0.1, -0.4), (-0.2, -0.3), (0.3, 0.35),
...                                      (-0.35, -0.1), (0.2, -0.2), (-0.1, 0.4)])]
>>> img = [camera.project_points(obj, r, t, dt.default_K(), dt.default_dist()) + rng.normal(0, 0.05, (35, 2))
...        for r, t in poses]
>>> q = calibrate([obj] * len(img), img, dt.IMAGE_SIZE).quality()
>>> q.verdict, [f.code for f in q.findings]
('bad', ['uncertainty'])
>>> print(q.findings[0].advice)  # doctest: +ELLIPSIS
hold the board next in the ... of the image (filling it, tilted), where the uncertainty is largest
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera import pixel_to_normalized, project_points, undistort_normalized
from .findings import Finding

__all__ = ["Finding", "Quality", "UncertaintyMap", "assess", "corner_noise", "residuals", "grid_indices",
           "projection_uncertainty", "image_region", "REGION_NAMES"]

#: no detector measures corners of an 8-bit image much better than this (pixels, per coordinate);
#: the noise used in the ratios never goes below it (exact synthetic points would divide by 0)
NOISE_FLOOR_PX = 0.01
#: residual sigma / corner noise: above the first the fit is doubtful, above the second bad
FIT_RATIO_DOUBTFUL, FIT_RATIO_BAD = 1.5, 3.0
#: a view whose RMS exceeds this many times the median view's fits "far worse than the others"
VIEW_OUTLIER_FACTOR = 3.0
#: a column/row mean offset counts when it is this many standard errors from 0 (and at least the noise)
OFFSET_Z = 6.0
#: ... in at least this share of the views (and in at least 2 views) it is a systematic offset
OFFSET_VIEW_SHARE = 0.25
#: a radial residual bias (mean over a radius band) counts above this many standard errors and
#: above this fraction of the corner noise
RADIAL_Z, RADIAL_FRACTION = 6.0, 0.5
#: mean correlation of the residual vectors of grid-neighbouring corners that counts as shared error
NEIGHBOUR_CORRELATION = 0.5
#: residuals this many times the noise, shared by neighbouring corners, are a bad (not doubtful) pattern
SYSTEMATIC_RATIO_BAD = 2.0
#: fewer views than this cannot tell a bad view from the rest
MIN_GOOD_VIEWS = 6
#: largest angle between a board normal and the mean normal, degrees: below the first bad, the second doubtful
#: (rows of the one table of belief, with the refusal's limit: dtscal_lib.limits)
from .limits import TILT_BAD_DEG, TILT_DOUBTFUL_DEG  # noqa: E402
#: mean 1-sigma projection uncertainty at the image corners, pixels: above the first doubtful, the second bad
#: (the image corners are extrapolated: no board corner is ever detected there)
CORNER_SIGMA_DOUBTFUL, CORNER_SIGMA_BAD = 1.0, 4.0

REGION_NAMES = (("top-left", "top", "top-right"), ("left", "centre", "right"),
                ("bottom-left", "bottom", "bottom-right"))
_SEVERITY = {"good": 0, "doubtful": 1, "bad": 2}


# =========================================================================== data types
@dataclass
class UncertaintyMap:
    """1-sigma projection uncertainty (worst direction, pixels) on a grid of pixels.

    u : (nu,) pixel columns of the grid;  v : (nv,) pixel rows
    sigma : (nv, nu) worst-direction standard deviation of the projection, pixels
    corners : (4, 2) pixels of the image corners (top-left, top-right, bottom-left, bottom-right)
    corner_sigma : (4,) worst-direction standard deviation there
    distance : distance (object-point unit) of the fixed 3-D points along their rays; ``inf`` for directions
    """

    u: np.ndarray
    v: np.ndarray
    sigma: np.ndarray
    corners: np.ndarray
    corner_sigma: np.ndarray
    distance: float

    @property
    def corner_mean(self) -> float:
        """The one number: mean 1-sigma at the four image corners, pixels."""
        return float(np.mean(self.corner_sigma))

    def worst_region(self) -> str:
        """Name of the ninth of the image (3 x 3) with the largest mean uncertainty."""
        h, w = self.v[-1] + 0.5, self.u[-1] + 0.5
        ri, ci = image_region(np.column_stack([np.repeat(self.u[None], len(self.v), 0).ravel(),
                                               np.repeat(self.v[:, None], len(self.u), 1).ravel()]), (w, h))
        means = np.full((3, 3), -1.0)
        for r in range(3):
            for c in range(3):
                sel = (ri == r) & (ci == c)
                if sel.any():
                    vals = self.sigma.ravel()[sel]  # NaN: the lens model cannot even be inverted there
                    means[r, c] = np.inf if np.isnan(vals).any() else vals.mean()
        r, c = np.unravel_index(int(np.argmax(means)), means.shape)
        return REGION_NAMES[r][c]


@dataclass
class Quality:
    """What :func:`assess` found."""

    verdict: str
    findings: list[Finding]
    noise_sigma: float
    noise_points: int
    fit_sigma: float
    per_view_rms: np.ndarray
    residuals: list[np.ndarray]
    uncertainty: UncertaintyMap | None
    corner_counts: np.ndarray  # (3, 3) observed corners per ninth of the image
    help_region: str
    tilt_spread_deg: float
    #: the report page when one was written (:func:`dtscal_lib.report.quality_for_run`)
    report_path: object = None

    @property
    def noise_model(self) -> str:
        return (f"independent Gaussian corner noise, sigma {self.noise_sigma:.3f} px per coordinate, measured "
                f"model-free from {self.noise_points} interior corners against the quadratic through their "
                "8 grid neighbours")

    def warnings(self) -> list[str]:
        """One line per finding, each saying what to do; empty when the verdict is good."""
        return [f.warning() for f in self.findings]

    def views_to_drop(self) -> list[int]:
        out: set[int] = set()
        for f in self.findings:
            if f.code in ("outlier_views", "column_offset", "row_offset"):
                out.update(f.views)
        return sorted(out)

    def to_dict(self) -> dict:
        u = self.uncertainty
        return {
            "verdict": self.verdict,
            "findings": [f.to_dict() for f in self.findings],
            "warnings": self.warnings(),
            "noise_model": self.noise_model,
            "noise_sigma_px": float(self.noise_sigma),
            "fit_sigma_px": float(self.fit_sigma),
            "fit_to_noise": float(self.fit_sigma / max(self.noise_sigma, NOISE_FLOOR_PX)),
            "tilt_spread_deg": float(self.tilt_spread_deg),
            "projection_uncertainty": None if u is None else {
                "corner_sigma_px": None if np.isnan(u.corner_mean) else float(u.corner_mean),
                "per_corner_sigma_px": [float(s) for s in u.corner_sigma],
                "max_sigma_px": float(max(np.nanmax(u.sigma), np.nanmax(u.corner_sigma))),
                "unprojectable_share": float(np.isnan(u.sigma).mean()),
                "distance": float(u.distance),
                "worst_region": u.worst_region(),
            },
            "more_data_where": self.help_region,
        }


# =========================================================================== residuals and grid
def residuals(result) -> list[np.ndarray]:
    """Per view (N_i, 2) ``projected - observed`` pixels of a result that carries its observations."""
    _need_observations(result)
    return [project_points(np.column_stack([o, np.zeros(len(o))]), r, t, result.K, result.dist) - p
            for o, p, r, t in zip(result.object_points, result.image_points, result.rvecs, result.tvecs)]


def _need_observations(result) -> None:
    if not getattr(result, "object_points", None) or len(result.object_points) != result.n_views:
        from .errors import CalibrationError

        raise CalibrationError("this calibration result does not carry its views (object_points, image_points); "
                               "recompute it with dtscal_lib.calibration.calibrate to judge its quality")


def grid_indices(obj: np.ndarray) -> np.ndarray:
    """(N, 2) int (column, row) of each board-plane point of a regular grid, from its coordinates.

    Columns are the distinct x values in increasing order, rows the distinct y values.
    """
    obj = np.asarray(obj, dtype=np.float64)[:, :2]
    out = np.zeros((len(obj), 2), dtype=int)
    for k in range(2):
        x = obj[:, k]
        steps = np.diff(np.unique(x))
        tol = 1e-6 * max(float(np.ptp(x)), 1e-12)
        pitch = steps[steps > tol].min() if np.any(steps > tol) else 1.0
        out[:, k] = np.rint((x - x.min()) / pitch).astype(int)
    return out


# offsets of the 8 neighbours and the weights of the least-squares quadratic through them at (0, 0)
_RING = np.array([(dc, dr) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dc, dr) != (0, 0)], dtype=float)
_RING_W = np.linalg.pinv(np.column_stack([np.ones(8), _RING[:, 0], _RING[:, 1], _RING[:, 0] ** 2,
                                          _RING[:, 0] * _RING[:, 1], _RING[:, 1] ** 2]))[0]
_RING_GAIN = float(np.sqrt(1.0 + (_RING_W ** 2).sum()))  # std of (observed - predicted) / sigma


def _prediction_errors(obj: np.ndarray, img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Errors (M, 2) of interior corners against the quadratic through their 8 neighbours, and their indices."""
    g = grid_indices(obj)
    lookup = {(int(c), int(r)): i for i, (c, r) in enumerate(g)}
    errs, idx = [], []
    for i, (c, r) in enumerate(g):
        nb = [lookup.get((int(c + dc), int(r + dr))) for dc, dr in _RING.astype(int)]
        if any(n is None for n in nb):
            continue
        errs.append(img[i] - _RING_W @ img[nb])
        idx.append(i)
    return np.reshape(errs, (-1, 2)), np.asarray(idx, dtype=int)


def corner_noise(object_points, image_points) -> tuple[float, int]:
    """Model-free corner noise of a set of views: ``(sigma per coordinate in pixels, corners used)``.

    Each interior corner (all 8 grid neighbours detected) is predicted by the least-squares
    quadratic in grid coordinates through its neighbours; ``sigma = 1.4826 * median|error| / g`` with
    ``g = sqrt(1 + sum w^2)`` the prediction's noise gain, so a few corners pulled off by clutter do
    not inflate it. Returns ``(nan, 0)`` when no view has an interior corner.
    """
    errs = [_prediction_errors(np.asarray(o, float)[:, :2], np.asarray(p, float).reshape(-1, 2))[0]
            for o, p in zip(object_points, image_points)]
    e = np.concatenate(errs) if errs else np.zeros((0, 2))
    if len(e) == 0:
        return float("nan"), 0
    return float(1.4826 * np.median(np.abs(e)) / _RING_GAIN), len(e)


# =========================================================================== projection uncertainty
def _full_covariance(result) -> tuple[np.ndarray, int]:
    """``sigma^2 (J^T J)^-1`` over all parameters ``[intrinsics, pose_0 (rvec, t), pose_1, ...]``."""
    from .calibration import _dist_indices, _normal_blocks, _Problem

    dist_idx = _dist_indices(result.model, fix_k3="k3" not in result.std)
    problem = _Problem([np.asarray(o)[:, :2] for o in result.object_points], result.image_points,
                       result.skew, dist_idx)
    theta = np.concatenate([[result.K[0, 0], result.K[1, 1], result.K[0, 2], result.K[1, 2]],
                            [result.K[0, 1]] if result.skew else [], result.dist[dist_idx]])
    poses = np.column_stack([result.rvecs, result.tvecs])
    rs, Jis, Jes = problem.linearize(theta, poses)
    A, Bs, Cs, _, _ = _normal_blocks(rs, Jis, Jes)
    n, V = problem.n_intr, len(poses)
    N = np.zeros((n + 6 * V, n + 6 * V))
    N[:n, :n] = A
    for v in range(V):
        s = slice(n + 6 * v, n + 6 * v + 6)
        N[:n, s] = Bs[v]
        N[s, :n] = Bs[v].T
        N[s, s] = Cs[v]
    return result.sigma ** 2 * np.linalg.inv(N), n


def _projection_jacobian(P: np.ndarray, K: np.ndarray, dist: np.ndarray, skew: bool, dist_idx):
    """Pixels (M, 2) of camera-frame points P (M, 3), d q / d P (M, 2, 3) and d q / d intrinsics (M, 2, n)."""
    K0 = K.copy()
    K0[0, 1] = 0.0
    uv0, J = cv2.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K0, dist)
    uv0 = uv0.reshape(-1, 2)
    J = J.reshape(-1, 2, J.shape[1])
    s, fy = K[0, 1], K[1, 1]
    yd = (uv0[:, 1] - K[1, 2]) / fy
    q = np.column_stack([uv0[:, 0] + s * yd, uv0[:, 1]])
    dP = J[:, :, 3:6].copy()  # d/dt at t = 0 equals d/dP
    dP[:, 0] += (s / fy) * dP[:, 1]
    cols = [6, 7, 8, 9] + [10 + i for i in dist_idx]
    dI = J[:, :, cols].copy()
    nd = len(dist_idx)
    if nd:
        dI[:, 0, 4:] += (s / fy) * J[:, 1, 10:][:, dist_idx]
    if skew:
        dI = np.concatenate([dI[:, :, :4], np.stack([yd, np.zeros_like(yd)], axis=1)[:, :, None], dI[:, :, 4:]],
                            axis=2)
    return q, dP, dI


def _rays(result, pix: np.ndarray) -> np.ndarray:
    """Unit rays (M, 3) of pixels; NaN where the distortion model cannot be inverted (far outside the data)."""
    from .errors import DtscalError

    xy = pixel_to_normalized(pix, result.K)
    try:
        und = undistort_normalized(xy, result.dist)
    except DtscalError:
        und = np.full_like(xy, np.nan)
        for i, p in enumerate(xy):
            try:
                und[i] = undistort_normalized(p[None], result.dist)[0]
            except DtscalError:
                pass
    ray = np.column_stack([und, np.ones(len(und))])
    return ray / np.linalg.norm(ray, axis=1, keepdims=True)


def projection_uncertainty(result, pixels, *, distance: float | None = None, cov=None) -> np.ndarray:
    """Covariance (M, 2, 2) of the projection of the fixed 3-D points seen at ``pixels``.

    The point seen at pixel ``q`` is taken at ``distance`` along its ray (default: the median
    distance of the boards, where the calibration is at its best; ``np.inf``: the ray's direction).
    As in mrcal (its original "mean-frames" method), the point is held fixed in the frames of the
    boards, not in the camera frame: the camera frame is itself only known through the board poses,
    and a change of ``cx`` that a small rotation of every pose compensates moves no projection. So
    the point is mapped into every board frame with the solved poses, back with perturbed poses,
    averaged, and projected with perturbed intrinsics; the Jacobian of that with respect to all
    parameters (intrinsics and every pose) is propagated through their joint covariance
    ``sigma^2 (J^T J)^-1``.

    Parameters
    ----------
    result : CalibrationResult that carries its views
    pixels : (M, 2) float64 pixels
    distance : object-point unit (metres for the Duckietown board)
    cov : optional precomputed full covariance (from :func:`_full_covariance`)
    """
    from .calibration import _dist_indices

    _need_observations(result)
    pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    C, n = _full_covariance(result) if cov is None else cov
    if distance is None:
        distance = float(np.median(np.linalg.norm(result.tvecs, axis=1)))
    ray = _rays(result, pix)
    at_infinity = not np.isfinite(distance)
    P = ray if at_infinity else distance * ray
    dist_idx = _dist_indices(result.model, fix_k3="k3" not in result.std)
    _, dqdP, dqdI = _projection_jacobian(P, result.K, result.dist, result.skew, dist_idx)
    V = result.n_views
    G = np.zeros((len(P), 2, C.shape[0]))
    G[:, :, :n] = dqdI
    h = 1e-6
    for v in range(V):
        R0 = cv2.Rodrigues(result.rvecs[v].reshape(3, 1))[0]
        t0 = np.zeros(3) if at_infinity else result.tvecs[v]
        Xb = (P - t0) @ R0  # the point in board v's frame: R0^T (P - t0)
        for k in range(3):
            dr = np.zeros(3)
            dr[k] = h
            dR = (cv2.Rodrigues((result.rvecs[v] + dr).reshape(3, 1))[0]
                  - cv2.Rodrigues((result.rvecs[v] - dr).reshape(3, 1))[0]) / (2 * h)
            dPdr = Xb @ dR.T / V  # the mean over boards moves by 1/V of board v's motion
            G[:, :, n + 6 * v + k] = np.einsum("mij,mj->mi", dqdP, dPdr)
        if not at_infinity:
            G[:, :, n + 6 * v + 3: n + 6 * v + 6] = dqdP / V
    GC = (G.reshape(-1, G.shape[2]) @ C).reshape(G.shape)
    return np.einsum("mip,mjp->mij", GC, G)


def worst_direction_sigma(cov: np.ndarray) -> np.ndarray:
    """sqrt of the largest eigenvalue of each (2, 2) covariance: (M,) pixels."""
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    return np.sqrt(0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b ** 2))


def uncertainty_map(result, *, step: int = 20, distance: float | None = None) -> UncertaintyMap:
    """:func:`projection_uncertainty` (worst direction) on a grid every ``step`` pixels and at the image corners."""
    w, h = result.image_size
    u = np.arange(step / 2, w, step, dtype=float)
    v = np.arange(step / 2, h, step, dtype=float)
    corners = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
    grid = np.column_stack([np.tile(u, len(v)), np.repeat(v, len(u))])
    cov = _full_covariance(result)
    d = float(np.median(np.linalg.norm(result.tvecs, axis=1))) if distance is None else float(distance)
    s = worst_direction_sigma(projection_uncertainty(result, np.vstack([grid, corners]), distance=d, cov=cov))
    return UncertaintyMap(u, v, s[:-4].reshape(len(v), len(u)), corners, s[-4:], d)


def image_region(pixels, image_size) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) in 0..2 of the ninth of the image each pixel lies in."""
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    w, h = image_size
    return (np.clip((p[:, 1] * 3 // h).astype(int), 0, 2), np.clip((p[:, 0] * 3 // w).astype(int), 0, 2))


# =========================================================================== checks
def _board_axis_components(obj: np.ndarray, img: np.ndarray, res: np.ndarray) -> np.ndarray:
    """Residuals (N, 2) resolved along the board's x and y axes as seen in the image, in pixels."""
    from .calibration import plane_homography

    H = plane_homography(obj, img)
    x = np.column_stack([obj, np.ones(len(obj))]) @ H.T
    wgt = x[:, 2]
    # d(pixel)/d(board) of the homography at each point
    J = np.empty((len(obj), 2, 2))
    for k in range(2):
        J[:, :, k] = (H[:2, k][None, :] * wgt[:, None] - x[:, :2] * H[2, k]) / wgt[:, None] ** 2
    b = np.linalg.solve(J, res[:, :, None])[:, :, 0]  # board-plane displacement
    return b * np.linalg.norm(J, axis=1)  # back to pixels along each axis


def _line_offsets(obj_list, img_list, res, noise) -> dict[tuple[int, int], dict[int, float]]:
    """``{(axis, line): {view: mean offset px}}`` for the grid columns (axis 0) and rows (axis 1) whose
    residuals along the board's axis share one offset in at least ``OFFSET_VIEW_SHARE`` of the views."""
    offsets: dict[tuple[int, int], dict[int, float]] = {}
    for v, (o, p, e) in enumerate(zip(obj_list, img_list, res)):
        g = grid_indices(o)
        comp = _board_axis_components(o, p, e)
        for axis in (0, 1):
            for line in np.unique(g[:, axis]):
                sel = g[:, axis] == line
                m = float(comp[sel, axis].mean())
                if abs(m) > max(OFFSET_Z * noise / np.sqrt(sel.sum()), noise):
                    offsets.setdefault((axis, int(line)), {})[v] = m
    return {k: d for k, d in offsets.items() if len(d) >= max(2, OFFSET_VIEW_SHARE * len(res))}


def _without_line(result, obj_list, img_list, axis: int, line: int):
    """Re-calibrate without one grid column/row; returns the fit and, per view, that line's mean offset."""
    from .calibration import calibrate
    from .errors import DtscalError

    keep = [grid_indices(o)[:, axis] != line for o in obj_list]
    try:
        fit = calibrate([o[k] for o, k in zip(obj_list, keep)], [p[k] for p, k in zip(img_list, keep)],
                        result.image_size, model=result.model, skew=result.skew, fix_k3="k3" not in result.std)
    except (DtscalError, cv2.error, np.linalg.LinAlgError):  # e.g. too few points left in a view
        return None, None
    means = []
    for o, p, k, r, t in zip(obj_list, img_list, keep, fit.rvecs, fit.tvecs):
        o3 = np.column_stack([o, np.zeros(len(o))])
        e = project_points(o3, r, t, fit.K, fit.dist) - p
        means.append(float(_board_axis_components(o, p, e)[~k, axis].mean()))
    return fit, np.array(means)


def _offset_findings(result, obj_list, img_list, res, noise, rounds: int = 2) -> list[Finding]:
    """Columns or rows of corners offset the same way in many views, located by leaving each suspect out.

    The residuals of the full fit smear one bad column over its neighbours (the camera absorbs part
    of it), so every flagged line is left out in turn; the one whose removal lowers the fit's sigma
    most is the cause, and its offsets against that fit name the views. Repeated once more for a
    second bad line.
    """
    out = []
    names = ("column", "row")
    for _ in range(rounds):
        flagged = _line_offsets(obj_list, img_list, res, noise)
        if not flagged:
            break
        size = {k: float(np.median(np.abs(list(d.values())))) for k, d in flagged.items()}
        top = max(size.values())
        best = None
        for axis, line in [k for k in flagged if size[k] >= 0.5 * top]:  # the strongest suspects only
            fit, means = _without_line(result, obj_list, img_list, axis, line)
            if fit is not None and (best is None or fit.sigma < best[2].sigma):
                best = (axis, line, fit, means)
        if best is None:
            break
        axis, line, fit, means = best
        n_line = int(np.sum(grid_indices(obj_list[0])[:, axis] == line))
        off = np.abs(means) > max(OFFSET_Z * noise / np.sqrt(n_line), noise)
        if not off.any():
            break
        sign = np.sign(np.median(means[off]))
        consistent = float(np.mean(np.sign(means[off]) == sign))
        excess_drop = 1.0 - (fit.sigma ** 2 - noise ** 2) / max(result.sigma ** 2 - noise ** 2, 1e-300)
        views = [int(v) for v in np.flatnonzero(off & (np.sign(means) == sign))]
        # a pulled detector shifts the line the same way (towards the board's edge) in every view and
        # leaving it out explains the data; a lens the model cannot follow shifts it one way or the
        # other depending on where the board is, and leaving it out only helps a little
        explained = fit.sigma <= FIT_RATIO_DOUBTFUL * noise or (consistent >= 0.9 and excess_drop >= 0.75)
        if len(views) < max(2, OFFSET_VIEW_SHARE * len(res)) or not explained:
            break
        name = names[axis]
        size = float(np.median(np.abs(means[views])))
        out.append(Finding(
            f"{name}_offset", "bad",
            f"{name} {line} of the board's corners is offset by {size:.2f} px (median) along the board's "
            f"{'xy'[axis]} axis in {len(views)} of {len(res)} views (views {_list(views)}); without that {name} "
            f"the residual sigma drops from {result.sigma:.3f} to {fit.sigma:.3f} px. The same corners are "
            "wrong the same way view after view: the detector was pulled (by the board's edge, a printed "
            "outline or clutter), this is not noise",
            f"drop views {_list(views)} or re-detect with a corner refinement that stays within each corner's "
            f"own four squares; look at {name} {line} on those images", views))
        # look for a second bad line in the fit without this one
        keep = [grid_indices(o)[:, axis] != line for o in obj_list]
        obj_list = [o[k] for o, k in zip(obj_list, keep)]
        img_list = [p[k] for p, k in zip(img_list, keep)]
        res = [project_points(np.column_stack([o, np.zeros(len(o))]), r, t, fit.K, fit.dist) - p
               for o, p, r, t in zip(obj_list, img_list, fit.rvecs, fit.tvecs)]
        result = fit
    return out


def _radial_finding(result, res, noise) -> Finding | None:
    """A radial residual that depends on the distance from the principal point: the lens model is too simple."""
    c = np.array([result.K[0, 2], result.K[1, 2]])
    pts = np.concatenate([np.asarray(p).reshape(-1, 2) for p in result.image_points])
    e = np.concatenate(res)
    d = pts - c
    r = np.linalg.norm(d, axis=1)
    if len(r) < 40:
        return None
    radial = np.einsum("ij,ij->i", e, d / np.maximum(r, 1e-9)[:, None])
    edges = np.quantile(r, np.linspace(0, 1, 9))
    band = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, 7)
    worst = None
    for b in range(8):
        sel = band == b
        m = float(radial[sel].mean())
        if abs(m) > max(RADIAL_Z * noise / np.sqrt(sel.sum()), RADIAL_FRACTION * noise):
            if worst is None or abs(m) > abs(worst[0]):
                worst = (m, edges[b], edges[b + 1])
    if worst is None:
        return None
    m, r0, r1 = worst
    richer = _richer_model(result)
    return Finding("radial", "bad" if abs(m) > 2 * noise else "doubtful",
                   f"corners {r0:.0f}-{r1:.0f} px from the principal point are off by {m:+.2f} px radially on "
                   f"average (corner noise {noise:.3f} px): a radial pattern the {result.model} distortion "
                   "model cannot absorb",
                   f"{richer}; and show the board in the image corners, where distortion is strongest")


def _richer_model(result) -> str:
    if result.model == "radial2":
        return "use --model plumb_bob (radial2 has no tangential terms)"
    return "estimate k3 as well (or use a richer lens model)"


def _neighbour_correlation(obj_list, res) -> float:
    """Mean normalised dot product of the residual vectors of grid-neighbouring corners (0 for noise)."""
    num = den = 0.0
    for o, e in zip(obj_list, res):
        g = grid_indices(o)
        lookup = {(int(a), int(b)): i for i, (a, b) in enumerate(g)}
        for i, (a, b) in enumerate(g):
            for da, db in ((1, 0), (0, 1)):
                j = lookup.get((int(a + da), int(b + db)))
                if j is not None:
                    num += float(e[i] @ e[j])
                    den += 0.5 * float(e[i] @ e[i] + e[j] @ e[j])
    return num / den if den > 0 else 0.0


def _list(views) -> str:
    views = [int(v) for v in views]
    return ", ".join(map(str, views[:12])) + (f" ... ({len(views)} in all)" if len(views) > 12 else "")


def assess(result, *, uncertainty: bool = True, distance: float | None = None) -> Quality:
    """Judge a calibration: verdict (``good`` / ``doubtful`` / ``bad``), findings with advice, uncertainty.

    Parameters
    ----------
    result : CalibrationResult (it carries its views)
    uncertainty : also compute the projection-uncertainty map (a few hundred ms for 70 views)
    distance : distance of the fixed points of the uncertainty map (default: median board distance)
    """
    from .calibration import board_normal_spread

    _need_observations(result)
    obj = [np.asarray(o, float)[:, :2] for o in result.object_points]
    img = [np.asarray(p, float).reshape(-1, 2) for p in result.image_points]
    res = residuals(result)
    noise_raw, n_noise = corner_noise(obj, img)
    noise = max(noise_raw, NOISE_FLOOR_PX) if np.isfinite(noise_raw) else max(result.sigma, NOISE_FLOOR_PX)
    findings: list[Finding] = []
    pv = np.asarray(result.per_view_rms)

    ratio = result.sigma / noise
    if ratio > FIT_RATIO_DOUBTFUL:
        findings.append(Finding(
            "fit", "bad" if ratio > FIT_RATIO_BAD else "doubtful",
            f"the residuals (sigma {result.sigma:.3f} px per coordinate, RMS {result.rms:.3f} px) are "
            f"{ratio:.1f} times the corner noise of these images ({noise:.3f} px, measured without a model)",
            "the model does not explain the data: look at the findings below and the residual figures "
            "(dtscal calibrate-intrinsics --report DIR)"))

    limit = VIEW_OUTLIER_FACTOR * float(np.median(pv))
    bad_views = [int(v) for v in np.flatnonzero((pv > limit) & (pv / np.sqrt(2) > 2 * noise))]
    if bad_views:
        findings.append(Finding(
            "outlier_views", "doubtful",
            f"view(s) {_list(bad_views)} fit far worse than the others (RMS "
            f"{', '.join(f'{pv[v]:.2f}' for v in bad_views[:6])} px against a median of {np.median(pv):.3f} px)",
            f"drop view(s) {_list(bad_views)} (a wrong or blurred detection) and calibrate again", bad_views))

    line_findings = _offset_findings(result, obj, img, res, noise)
    findings += line_findings
    # a bad column or row also shows as radial and correlated residuals: report the cause, not its echoes
    radial = None if line_findings else _radial_finding(result, res, noise)
    if radial is not None:
        findings.append(radial)
    rho = _neighbour_correlation(obj, res)
    if rho > NEIGHBOUR_CORRELATION and ratio > 1.2 and not line_findings:
        findings.append(Finding(
            # above 2x the noise the systematic part of the residual is larger than the noise itself
            # (sqrt(ratio^2 - 1) > 1.7): the parameters are biased far beyond their standard deviations
            "neighbour_correlation", "doubtful" if ratio <= SYSTEMATIC_RATIO_BAD else "bad",
            f"neighbouring corners share their error (correlation {rho:.2f} of adjacent residuals, 0 for noise) "
            f"and the residuals are {ratio:.1f} times the corner noise: a pattern the {result.model} model "
            "cannot absorb, which biases the parameters beyond their standard deviations",
            f"{_richer_model(result)}; check that the board is flat and its squares are the size given"))

    if result.n_views < MIN_GOOD_VIEWS:
        findings.append(Finding(
            "few_views", "doubtful",
            f"only {result.n_views} views: too few to tell a wrong view from the rest",
            f"collect at least {MIN_GOOD_VIEWS} (better 20 or more) views at different places and tilts"))
    spread = board_normal_spread(result.rvecs)
    if spread < TILT_DOUBTFUL_DEG:
        findings.append(Finding(
            "parallel_views", "bad" if spread < TILT_BAD_DEG else "doubtful",
            f"the boards are nearly parallel: every board normal is within {spread:.1f} degrees of their mean",
            "tilt the board left/right and up/down by 20-45 degrees in further views"))

    w, h = result.image_size
    allpts = np.concatenate(img)
    ri, ci = image_region(allpts, (w, h))
    counts = np.zeros((3, 3), dtype=int)
    np.add.at(counts, (ri, ci), 1)
    umap = None
    if uncertainty:
        try:
            umap = uncertainty_map(result, distance=distance)
        except np.linalg.LinAlgError:
            umap = None
    if umap is not None:
        help_region = umap.worst_region()
    else:
        r, c = np.unravel_index(int(np.argmin(counts)), counts.shape)
        help_region = REGION_NAMES[r][c]
    if umap is not None and np.isnan(umap.corner_mean):
        findings.append(Finding(
            "uncertainty", "bad",
            "the distortion model cannot be inverted at the image corners: fitted without corners there, "
            "it folds over and does not describe the lens",
            f"hold the board next in the {help_region} of the image and in the other image corners"))
    elif umap is not None and umap.corner_mean > CORNER_SIGMA_DOUBTFUL:
        findings.append(Finding(
            "uncertainty", "bad" if umap.corner_mean > CORNER_SIGMA_BAD else "doubtful",
            f"a pixel at the image corners can move by {umap.corner_mean:.2f} px (1 sigma) within the "
            "parameters' uncertainty",
            f"hold the board next in the {help_region} of the image (filling it, tilted), where the uncertainty "
            "is largest"))
    verdict = max((f.severity for f in findings), key=_SEVERITY.__getitem__, default="good")
    return Quality(verdict, findings, float(noise), n_noise, float(result.sigma), pv, res, umap, counts,
                   help_region, spread)


def monte_carlo_projection(result, pixels, *, runs: int = 50, distance: float | None = None, seed: int = 0,
                           noise: float | None = None) -> np.ndarray:
    """Projections (runs, M, 2) of the fixed points seen at ``pixels``, re-calibrating on resampled noise.

    The check of :func:`projection_uncertainty` without linearisation: the solved camera and poses
    give perfect corners, Gaussian noise of ``noise`` px (default: the fit's ``sigma``) is added,
    the calibration is repeated (same model), and the same fixed 3-D points (held in the boards'
    frames, averaged over the boards) are projected with each run's intrinsics and poses. The
    spread over runs is what the uncertainty map predicts.
    """
    from .calibration import calibrate

    _need_observations(result)
    rng = np.random.default_rng(seed)
    pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    if distance is None:
        distance = float(np.median(np.linalg.norm(result.tvecs, axis=1)))
    P = distance * _rays(result, pix)
    R0 = [cv2.Rodrigues(r.reshape(3, 1))[0] for r in result.rvecs]
    Xb = [(P - t) @ R for R, t in zip(R0, result.tvecs)]
    obj = [np.column_stack([np.asarray(o)[:, :2], np.zeros(len(o))]) for o in result.object_points]
    perfect = [project_points(o, r, t, result.K, result.dist) for o, r, t in zip(obj, result.rvecs, result.tvecs)]
    s = result.sigma if noise is None else noise
    fix_k3 = "k3" not in result.std
    out = []
    for _ in range(runs):
        rr = calibrate(obj, [p + rng.normal(0.0, s, p.shape) for p in perfect], result.image_size,
                       model=result.model, skew=result.skew, fix_k3=fix_k3)
        Pm = np.mean([X @ cv2.Rodrigues(r.reshape(3, 1))[0].T + t for X, r, t in zip(Xb, rr.rvecs, rr.tvecs)],
                     axis=0)
        out.append(project_points(Pm, np.zeros(3), np.zeros(3), rr.K, rr.dist))
    return np.array(out)
