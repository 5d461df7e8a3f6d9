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

from dataclasses import dataclass, field

import cv2
import numpy as np

from .camera import KIT_SOLVER_MODELS, pixel_to_normalized, project_points, undistort_model
from .covariance import projection_covariance, rodrigues
from .errors import CalibrationError, DtscalError
from .findings import Evidence, Finding
from .lsq import dist_indices as _lsq_dist_indices

__all__ = ["Finding", "Quality", "UncertaintyMap", "assess", "corner_noise", "residuals", "grid_indices",
           "leave_out_outlier_corners", "corner_severity",
           "projection_uncertainty", "image_region", "consequences", "explain", "REGION_NAMES"]

#: no detector measures corners of an 8-bit image much better than this (pixels, per coordinate);
#: the noise used in the ratios never goes below it (exact synthetic points would divide by 0)
NOISE_FLOOR_PX = 0.01
#: the verdict's thresholds, each once in the one table of belief with its reason and data (dtscal_lib.limits):
#: residual sigma / corner noise (doubtful, bad); a view's RMS / the median view's; a grid line's offset in
#: standard errors and the share of views; a radial bias in standard errors and fraction of the noise; the
#: correlation of neighbouring corners' residuals; a shared pattern / noise that is bad; the fewest views that
#: can tell a bad view; the boards' tilt (bad, doubtful); the mean 1-sigma projection uncertainty at the image
#: corners, pixels (doubtful, bad)
from .limits import (  # noqa: E402
    CORNER_SIGMA_BAD,
    CORNER_SIGMA_DOUBTFUL,
    FIT_RATIO_BAD,
    FIT_RATIO_DOUBTFUL,
    MIN_GOOD_VIEWS,
    NEIGHBOUR_CORRELATION,
    OFFSET_VIEW_SHARE,
    OFFSET_Z,
    RADIAL_FRACTION,
    RADIAL_Z,
    LENS_SHARE,
    OUTLIER_CORNER_MAX_SHARE,
    OUTLIER_CORNER_MIN_PX,
    OUTLIER_CORNER_Z,
    SYSTEMATIC_RATIO_BAD,
    TILT_BAD_DEG,
    TILT_DOUBTFUL_DEG,
    UNEXPLAINED_RATIO_BAD,
    UNEXPLAINED_RATIO_DOUBTFUL,
    VIEW_OUTLIER_FACTOR,
)

#: a Duckiebot's camera over the ground, as the shipped default extrinsic homography says it is
#: (duckietown.md's ``camera_extrinsic/default.yaml`` with the default P, read back through
#: :func:`dtscal_lib.ground.camera_pose_from_homography`: 0.1016 m above the ground, 25.3 degrees below
#: the horizon, 0.079 m ahead of the wheel axle; checked in the tests). Metres and degrees, robot frame
#: (x forward, y left, z up).
NOMINAL_CAMERA_HEIGHT_M, NOMINAL_CAMERA_PITCH_DEG, NOMINAL_CAMERA_X_M = 0.10, 25.0, 0.08
#: where the consequences are stated: ground points this far ahead of the axle (metres); a lane
#: follower looks at markings between the two
CONSEQUENCE_DISTANCES_M = (0.30, 0.60)

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
    #: what the calibration means for a Duckiebot (:func:`consequences`); None without the uncertainty
    consequences: dict | None = None
    #: remarks that do not change the verdict (severity "good"): what explains a residual above the noise
    notes: list = field(default_factory=list)
    #: the calibration repeated without the outlier corners (finding ``outlier_corners``), else None
    without_outlier_corners: object = None
    #: the richer models fitted to these corners (:mod:`dtscal_lib.richer`), by name; None when not needed
    richer: dict | None = None

    def meaning(self) -> str:
        """The verdict and its consequences for a robot, in words a student can act on."""
        return explain(self)

    def summary_lines(self, sigma_method: str = "", width: int = 100) -> list[str]:
        """What the command line prints under the parameters: how sigma was computed, the consequences
        for a Duckiebot (one line) and :meth:`meaning` wrapped, each line indented by two spaces."""
        import textwrap

        out = [f"  +- is 1 sigma: {sigma_method}"] if sigma_method else []
        c = self.consequences
        if c:
            g = [f"{100 * r['ahead_m']:.0f} cm ahead +-{r['ground_sigma_cm']:.2g} cm" for r in c["ground"]
                 if r["ground_sigma_cm"] is not None]
            corner = "n/a" if c["corner_sigma_px"] is None else f"+-{c['corner_sigma_px']:.2f} px"
            out.append(f"  on a Duckiebot: ground point {', '.join(g) or 'outside the image'}; image corners {corner} "
                       f"(1 sigma, each known to +-{100 * c['relative_uncertainty']:.0f} %)")
        out += textwrap.wrap(self.meaning(), width, initial_indent="  ", subsequent_indent="  ")
        return out

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
            "notes": [n.to_dict() for n in self.notes],
            "richer_models": None if self.richer is None else {
                k: {"sigma_px": float(f.sigma), "rms_px": float(f.rms), "dist_terms": list(f.dist_names),
                    "warp_mm": [float(1000.0 * w) for w in f.warp]} for k, f in self.richer.items()},
            "consequences": self.consequences,
            "meaning": self.meaning(),
        }


# =========================================================================== residuals and grid
def residuals(result) -> list[np.ndarray]:
    """Per view (N_i, 2) ``projected - observed`` pixels of a result that carries its observations."""
    _need_observations(result)
    return residuals_of(result, result.object_points, result.image_points)


def residuals_of(fit, obj_list, img_list) -> list[np.ndarray]:
    """Per view (N_i, 2) ``projected - observed`` pixels of board points ``obj_list`` seen at ``img_list``
    through a fit's camera and poses (all views in one projection; skew honoured)."""
    counts = [len(o) for o in obj_list]
    view = np.repeat(np.arange(len(obj_list)), counts)
    xy = np.concatenate([np.asarray(o, dtype=np.float64)[:, :2] for o in obj_list])
    R, _ = rodrigues(np.asarray(fit.rvecs, dtype=np.float64), jacobian=False)
    Rv = R[view]
    P = Rv[:, :, 0] * xy[:, :1] + Rv[:, :, 1] * xy[:, 1:] + np.asarray(fit.tvecs, dtype=np.float64)[view]
    q = project_points(P, np.zeros(3), np.zeros(3), fit.K, fit.dist, model=getattr(fit, "model", "plumb_bob"))
    obs = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in img_list])
    return np.split(q - obs, np.cumsum(counts)[:-1])


def _dist_idx(fit) -> list[int]:
    """The distortion terms a fit estimated (indices into ``[k1, k2, p1, p2, k3]``)."""
    return _lsq_dist_indices(getattr(fit, "model", "plumb_bob"), fit.std)


def _need_observations(result) -> None:
    if not getattr(result, "object_points", None) or len(result.object_points) != result.n_views:
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


def _grid_groups(object_points) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Views that show the same points of the same grid, so that their checks run on stacked arrays.

    Returns ``[(views, obj (N, 2), grid (N, 2) int)]``, every view in exactly one group.
    """
    groups: dict[bytes, list] = {}
    for v, o in enumerate(object_points):
        o = np.ascontiguousarray(np.asarray(o, dtype=np.float64)[:, :2])
        groups.setdefault(o.tobytes() + bytes(str(o.shape), "ascii"), [o, []])[1].append(v)
    return [(np.asarray(views), o, grid_indices(o)) for o, views in groups.values()]


def _ring_neighbours(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interior corners of a grid (all 8 neighbours present): their indices (M,) and the neighbours' (M, 8)."""
    lookup = {(int(c), int(r)): i for i, (c, r) in enumerate(g)}
    idx, nbs = [], []
    for i, (c, r) in enumerate(g):
        nb = [lookup.get((int(c + dc), int(r + dr))) for dc, dr in _RING.astype(int)]
        if all(n is not None for n in nb):
            idx.append(i)
            nbs.append(nb)
    return np.asarray(idx, dtype=int), np.asarray(nbs, dtype=int).reshape(-1, 8)


def corner_noise(object_points, image_points) -> tuple[float, int]:
    """Model-free corner noise of a set of views: ``(sigma per coordinate in pixels, corners used)``.

    Each interior corner (all 8 grid neighbours detected) is predicted by the least-squares
    quadratic in grid coordinates through its neighbours; ``sigma = 1.4826 * median|error| / g`` with
    ``g = sqrt(1 + sum w^2)`` the prediction's noise gain, so a few corners pulled off by clutter do
    not inflate it. Returns ``(nan, 0)`` when no view has an interior corner.
    """
    errs = []
    for views, _, g in _grid_groups(object_points):
        idx, nb = _ring_neighbours(g)
        if len(idx):
            p = np.stack([np.asarray(image_points[v], dtype=np.float64).reshape(-1, 2) for v in views])
            errs.append((p[:, idx] - np.einsum("k,vmkc->vmc", _RING_W, p[:, nb])).reshape(-1, 2))
    e = np.concatenate(errs) if errs else np.zeros((0, 2))
    if len(e) == 0:
        return float("nan"), 0
    return float(1.4826 * np.median(np.abs(e)) / _RING_GAIN), len(e)


# =========================================================================== projection uncertainty
def _uncertainty_inputs(blocks):
    """The normal-equation blocks and the intrinsics' covariance the projection uncertainty propagates.

    The noise model's, ``sigma^2 S^-1`` (:mod:`dtscal_lib.covariance`), as mrcal's
    ``projection_uncertainty`` propagates its ``observed_pixel_uncertainty``: the projection uncertainty
    is what the corner noise alone leaves, and it agrees with mrcal's on the same corners and model
    (``benchmarks/bench_mrcal.py``, 1.03x: the kit's sigma divides by ``2N - p``). The parameters' own
    standard deviations (``result.std``) stay the larger of that and the views' disagreement: on real
    photographs the views disagree 1.3-2.6x more than the noise says, because of the print's and the
    detector's shared pattern, which is a bias the verdict names (``unexplained_fit``, ``board_warp``), not a
    noise to spread over the image corners.
    """
    return blocks, blocks.sigma2 * np.linalg.inv(blocks.schur())


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
    xy = pixel_to_normalized(pix, result.K)
    und = undistort_model(xy, result.dist, getattr(result, "model", "plumb_bob"), strict=False)
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
    parameters (intrinsics and every pose) is propagated through their joint covariance: by default the
    noise model's ``sigma^2 (J^T J)^-1``, as mrcal (:func:`_uncertainty_inputs`; ``cov`` gives another
    intrinsic covariance, e.g. ``result.intrinsic_covariance()``), block by block
    (:func:`dtscal_lib.covariance.projection_covariance`): linear in the views, in time and memory.

    Parameters
    ----------
    result : CalibrationResult that carries its views
    pixels : (M, 2) float64 pixels
    distance : object-point unit (metres for the Duckietown board)
    cov : optional ``(NormalBlocks, intrinsic covariance)`` computed before (:func:`_uncertainty_inputs`)
    """
    _need_observations(result)
    pix = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    blocks, cov_i = _uncertainty_inputs(result.normal_blocks()) if cov is None else cov
    if distance is None:
        distance = float(np.median(np.linalg.norm(result.tvecs, axis=1)))
    ray = _rays(result, pix)
    at_infinity = not np.isfinite(distance)
    P = ray if at_infinity else distance * ray
    _, dqdP, dqdI = _projection_jacobian(P, result.K, result.dist, result.skew, _dist_idx(result))
    R0, dR0 = rodrigues(result.rvecs)
    W = np.einsum("vkij,vlj->vkil", dR0, R0)  # dR/dr_k R^T, a cross-product matrix [w_k]_x
    omegas = np.stack([W[:, :, 2, 1], W[:, :, 0, 2], W[:, :, 1, 0]], axis=1)  # (V, 3 axis, 3 k)
    with np.errstate(invalid="ignore"):  # NaN rays (a lens model that cannot be inverted) stay NaN
        return projection_covariance(blocks, cov_i, dqdI, dqdP, P, omegas,
                                     None if at_infinity else np.asarray(result.tvecs, dtype=np.float64))


def worst_direction_sigma(cov: np.ndarray) -> np.ndarray:
    """sqrt of the largest eigenvalue of each (2, 2) covariance: (M,) pixels."""
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    return np.sqrt(0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b ** 2))


def uncertainty_map(result, *, step: int = 20, distance: float | None = None, cov=None) -> UncertaintyMap:
    """:func:`projection_uncertainty` (worst direction) on a grid every ``step`` pixels and at the image corners.

    ``cov`` : optional ``(NormalBlocks, intrinsic covariance)`` computed before (:func:`_uncertainty_inputs`)
    """
    w, h = result.image_size
    u = np.arange(step / 2, w, step, dtype=float)
    v = np.arange(step / 2, h, step, dtype=float)
    corners = np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0]])
    grid = np.column_stack([np.tile(u, len(v)), np.repeat(v, len(u))])
    cov = _uncertainty_inputs(result.normal_blocks()) if cov is None else cov
    d = float(np.median(np.linalg.norm(result.tvecs, axis=1))) if distance is None else float(distance)
    s = worst_direction_sigma(projection_uncertainty(result, np.vstack([grid, corners]), distance=d, cov=cov))
    return UncertaintyMap(u, v, s[:-4].reshape(len(v), len(u)), corners, s[-4:], d)


def image_region(pixels, image_size) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) in 0..2 of the ninth of the image each pixel lies in."""
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    w, h = image_size
    return (np.clip((p[:, 1] * 3 // h).astype(int), 0, 2), np.clip((p[:, 0] * 3 // w).astype(int), 0, 2))


# =========================================================================== checks
def _board_axis_jacobians(fit, obj_list) -> list[np.ndarray]:
    """Per view (N_i, 2, 2) ``d pixel / d (board x, board y)`` at each board point, through the fitted camera."""
    counts = [len(o) for o in obj_list]
    view = np.repeat(np.arange(len(obj_list)), counts)
    xy = np.concatenate([np.asarray(o, dtype=np.float64)[:, :2] for o in obj_list])
    R, _ = rodrigues(np.asarray(fit.rvecs, dtype=np.float64), jacobian=False)
    Rv = R[view]
    P = Rv[:, :, 0] * xy[:, :1] + Rv[:, :, 1] * xy[:, 1:] + np.asarray(fit.tvecs, dtype=np.float64)[view]
    _, dqdP, _ = _projection_jacobian(P, fit.K, fit.dist, fit.skew, _dist_idx(fit))
    return np.split(np.matmul(dqdP, Rv[:, :, :2]), np.cumsum(counts)[:-1])


def _board_axis_components(J: np.ndarray, res: np.ndarray) -> np.ndarray:
    """Residuals (..., 2) resolved along the board's x and y axes as seen in the image, in pixels.

    ``J`` (..., 2, 2) is ``d pixel / d board`` at each point (:func:`_board_axis_jacobians`).
    """
    b = np.linalg.solve(J, res[..., None])[..., 0]  # board-plane displacement
    return b * np.linalg.norm(J, axis=-2)  # back to pixels along each axis


def _line_means(obj_list, comps):
    """``{(axis, line): (views, mean offsets, points on the line)}``: per grid column (axis 0) / row (axis 1),
    the mean of the board-axis residual components of its corners in each view (stacked per grid)."""
    out: dict[tuple[int, int], list] = {}
    for views, _, g in _grid_groups(obj_list):
        c = np.stack([comps[v] for v in views])  # (G, N, 2)
        for axis in (0, 1):
            for line in np.unique(g[:, axis]):
                sel = g[:, axis] == line
                out.setdefault((axis, int(line)), []).append((views, c[:, sel, axis].mean(axis=1), int(sel.sum())))
    return out


def _line_offsets(fit, obj_list, res, noise) -> dict[tuple[int, int], dict[int, float]]:
    """``{(axis, line): {view: mean offset px}}`` for the grid columns (axis 0) and rows (axis 1) whose
    residuals along the board's axis share one offset in at least ``OFFSET_VIEW_SHARE`` of the views."""
    comps = [_board_axis_components(J, e) for J, e in zip(_board_axis_jacobians(fit, obj_list), res)]
    offsets: dict[tuple[int, int], dict[int, float]] = {}
    for key, parts in _line_means(obj_list, comps).items():
        for views, m, count in parts:
            hit = np.abs(m) > max(OFFSET_Z * noise / np.sqrt(count), noise)
            for v, val in zip(views[hit], m[hit]):
                offsets.setdefault(key, {})[int(v)] = float(val)
    return {k: d for k, d in offsets.items() if len(d) >= max(2, OFFSET_VIEW_SHARE * len(res))}


def _without_line(refit, obj_list, img_list, axis: int, line: int):
    """Re-calibrate without one grid column/row; returns the fit and, per view, that line's mean offset."""
    keep = [grid_indices(o)[:, axis] != line for o in obj_list]
    try:
        fit = refit([o[k] for o, k in zip(obj_list, keep)], [p[k] for p, k in zip(img_list, keep)])
    except (DtscalError, cv2.error, np.linalg.LinAlgError):  # e.g. too few points left in a view
        return None, None
    res = residuals_of(fit, obj_list, img_list)
    comps = [_board_axis_components(J, e) for J, e in zip(_board_axis_jacobians(fit, obj_list), res)]
    means = np.array([float(c[~k, axis].mean()) for c, k in zip(comps, keep)])
    return fit, means


def _offset_findings(refit, result, obj_list, img_list, res, noise, rounds: int = 2) -> list[Finding]:
    """Columns or rows of corners offset the same way in many views, located by leaving each suspect out.

    The residuals of the full fit smear one bad column over its neighbours (the camera absorbs part
    of it), so every flagged line is left out in turn; the one whose removal lowers the fit's sigma
    most is the cause, and its offsets against that fit name the views. Repeated once more for a
    second bad line.
    """
    out = []
    names = ("column", "row")
    for _ in range(rounds):
        flagged = _line_offsets(result, obj_list, res, noise)
        if not flagged:
            break
        size = {k: float(np.median(np.abs(list(d.values())))) for k, d in flagged.items()}
        top = max(size.values())
        best = None
        for axis, line in [k for k in flagged if size[k] >= 0.5 * top]:  # the strongest suspects only
            fit, means = _without_line(refit, obj_list, img_list, axis, line)
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
        res = residuals_of(fit, obj_list, img_list)
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
    return Finding("radial", "bad" if abs(m) > 2 * noise else "doubtful",
                   f"corners {r0:.0f}-{r1:.0f} px from the principal point are off by {m:+.2f} px radially on "
                   f"average (corner noise {noise:.3f} px): a radial pattern the {result.model} distortion "
                   "model cannot absorb",
                   "show the board in the image corners, where distortion is strongest")


def _richer_model(result, noise: float, fits: dict | None) -> str:
    """Advice about the lens model, from the richer models actually fitted (:func:`_richer_fits`)."""
    if result.model == "equidistant":  # calibrated by OpenCV's fisheye module: no finer model is fitted
        return "use --model rational_polynomial (the fisheye model has no tangential terms), or check the board"
    if result.model == "rational_polynomial":
        return "the richest of ROS's models already: check the board's flatness and the detections"
    fits = _richer_fits(result, noise) if fits is None else fits
    lens = {k: f for k, f in fits.items() if k != "warp"}
    name, share = _best_lens(result, noise, lens)
    if name is not None and share >= LENS_SHARE:
        return f"{_LENS_ADVICE[name]}: fitted, it explains {100 * share:.0f} % of the residual above the noise"
    tried = ", ".join(_LENS_WORDS[k] for k in lens)
    return (f"not the lens model: {tried} fitted to these corners explain{'s' if len(lens) == 1 else ''} only "
            f"{100 * max(share, 0.0):.0f} % of the residual above the noise")


#: the lens candidates in words (the finding's message) and as advice
_LENS_WORDS = {"k3": "k3", "rational": "OpenCV's 8-coefficient rational model", "tangential": "tangential terms"}
_LENS_ADVICE = {"k3": "estimate k3 as well (dtscal_lib.calibration.calibrate(..., fix_k3=False); ROS keeps k3 = 0)",
                "rational": "use a richer lens model, OpenCV's 8-coefficient rational (not in ROS's camera_info: use "
                            "a lens with less distortion or keep to the well-modelled centre)",
                "tangential": "use --model plumb_bob (radial2 has no tangential terms)"}


def _richer_fits(result, noise: float | None = None) -> dict:
    """The finer lens models and the board warp fitted to a result's own corners (:mod:`dtscal_lib.richer`).

    The rational model holds every other lens candidate (k3, tangential terms), so they are fitted only when
    it explains at least :data:`LENS_SHARE` of the residual above ``noise`` (to name the smallest model that
    does): the common case costs two fits (``benchmarks/bench_calibrate.py``).
    """
    from .richer import candidates, excess_share, fit_richer

    if result.model not in ("plumb_bob", "radial2"):  # OpenCV's rational and fisheye results: nothing finer here
        return {}
    def fit(name):
        try:
            out[name] = fit_richer(result, name)
        except (cv2.error, np.linalg.LinAlgError, ValueError):
            pass

    out: dict = {}
    fit("rational")
    fit("warp")
    rational = out.get("rational")
    if noise is None or rational is None or excess_share(result.sigma, rational.sigma, noise) >= LENS_SHARE:
        for name in candidates(result):
            if name not in out:
                fit(name)
    return out


def _best_lens(result, noise, lens: dict) -> tuple[str | None, float]:
    """The lens candidate to name: the one with fewest parameters among those explaining at least
    :data:`LENS_SHARE` of the residual above the noise (k3 before the rational model: ROS's files hold k3),
    else the one explaining most."""
    from .richer import excess_share
    shares = {k: excess_share(result.sigma, f.sigma, noise) for k, f in lens.items()}
    enough = [k for k, v in shares.items() if v >= LENS_SHARE]
    if enough:
        k = min(enough, key=lambda n: (lens[n].n_params, -shares[n]))
        return k, shares[k]
    k = max(shares, key=shares.get, default=None)
    return (k, shares[k]) if k is not None and shares[k] > 0 else (None, 0.0)


def _fit_findings(result, noise: float):
    """The residual against the corner noise: who explains it.

    Returns ``(findings, notes, fits)``. Below :data:`FIT_RATIO_DOUBTFUL` nothing is fitted. Above it the
    finer lens models and mrcal's board warp are fitted (:mod:`dtscal_lib.richer`); the lens model is blamed
    (finding ``fit``, with the model to use) only when one explains at least :data:`LENS_SHARE` of the
    residual above the noise; a board warp that does is named with its size in mm (``board_warp``);
    otherwise the residual is the print and the detector's (a note, in words, with what it costs on the
    ground), and only beyond :data:`UNEXPLAINED_RATIO_DOUBTFUL` / :data:`UNEXPLAINED_RATIO_BAD` does it
    change the verdict.
    """
    from .richer import excess_share
    ratio = result.sigma / noise
    if not ratio > FIT_RATIO_DOUBTFUL:
        return [], [], None
    fits = _richer_fits(result, noise)
    lens = {k: f for k, f in fits.items() if k != "warp"}
    name, share = _best_lens(result, noise, lens)
    warp = fits.get("warp")
    wshare = excess_share(result.sigma, warp.sigma, noise) if warp is not None else 0.0
    head = (f"the residuals (sigma {result.sigma:.3f} px per coordinate, RMS {result.rms:.3f} px) are {ratio:.1f} "
            f"times the corner noise of these images ({noise:.3f} px, measured without a model)")
    findings, notes = [], []
    if name is not None and share >= LENS_SHARE and share >= wshare:
        f = lens[name]
        findings.append(Finding(
            "fit", "bad" if ratio > FIT_RATIO_BAD else "doubtful",
            f"{head}; {_LENS_WORDS[name]} brings sigma to {f.sigma:.3f} px ({100 * share:.0f} % of the residual "
            f"above the noise): the {result.model} model does not follow this lens",
            _LENS_ADVICE[name]))
        return findings, notes, fits
    warp_words = ""
    if warp is not None:
        mm = 1000.0 * warp.warp  # the board's unit is metres (dtscal_lib.boards)
        warp_words = (f"a board warp as mrcal fits it (the middle of the board {mm[0]:+.2f} mm along its x axis, "
                      f"{mm[1]:+.2f} mm along y, out of its plane) brings sigma to {warp.sigma:.3f} px "
                      f"({100 * wshare:.0f} % of the excess)")
    lens_words = (f"{' and '.join(_LENS_WORDS[k] for k in lens)} explain{'s' if len(lens) == 1 else ''} "
                  f"{'at most ' if len(lens) > 1 else ''}{100 * share:.0f} %" if lens
                  else "no finer lens model could be fitted")
    # with fewer views than min_good_views the two warp terms trade off against the few poses
    if warp is not None and wshare >= LENS_SHARE and result.n_views >= MIN_GOOD_VIEWS:
        findings.append(Finding(
            "board_warp", "bad" if ratio > UNEXPLAINED_RATIO_BAD else "doubtful",
            f"{head}; the board is not flat: {warp_words}; {lens_words} of the excess",
            "glue the printed board to a flat, rigid plate (glass, aluminium, thick acrylic) and calibrate again"))
        return findings, notes, fits
    excess = float(np.sqrt(max(result.sigma ** 2 - noise ** 2, 0.0)))
    text = (f"{head}: {excess:.3f} px per coordinate is neither noise nor the lens model "
            f"(fitted to these corners, {lens_words} of the excess{'; ' + warp_words if warp_words else ''}): "
            "it is the print and the detector (corners pulled the same way in neighbouring corners)")
    if ratio > UNEXPLAINED_RATIO_DOUBTFUL:
        findings.append(Finding(
            "unexplained_fit", "bad" if ratio > UNEXPLAINED_RATIO_BAD else "doubtful", text,
            "look at the residual figures (dtscal calibrate-intrinsics --report DIR): a blurred or mis-detected "
            "board, a board that moved during exposure, or a wrong square count"))
    else:
        notes.append(Finding("unexplained_fit", "good", text, ""))
    return findings, notes, fits


def _outlier_corners(refit, result, obj_list, img_list, res):
    """Single corners far off where the camera puts them: found, named, left out, the calibration repeated.

    A corner is an outlier when its residual (a 2-D vector) is longer than :data:`OUTLIER_CORNER_Z` robust
    standard deviations of the residual coordinates (``1.4826 * median |e|``) and than
    :data:`OUTLIER_CORNER_MIN_PX`. Returns ``(finding, refit)``
    or ``(None, None)``; more than :data:`OUTLIER_CORNER_MAX_SHARE` of the corners at once is not a few bad
    corners but a pattern (the other rules say which).
    """
    e = np.concatenate(res)
    scale = 1.4826 * float(np.median(np.abs(e)))
    if not scale > 0:
        return None, None, []
    limit = max(OUTLIER_CORNER_Z * scale, OUTLIER_CORNER_MIN_PX)
    hits = [(v, int(i), float(np.linalg.norm(r[i]))) for v, r in enumerate(res)
            for i in np.flatnonzero(np.linalg.norm(r, axis=1) > limit)]
    if not hits or len(hits) > max(1, OUTLIER_CORNER_MAX_SHARE * len(e)):
        return None, None, []
    keep = [np.ones(len(o), dtype=bool) for o in obj_list]
    for v, i, _ in hits:
        keep[v][i] = False
    try:
        fit = refit([o[k] for o, k in zip(obj_list, keep)], [p[k] for p, k in zip(img_list, keep)])
    except (DtscalError, cv2.error, np.linalg.LinAlgError):
        return None, None, []
    left = []
    for v, i, size in hits:
        c, r = grid_indices(obj_list[v])[i]
        left.append({"view": int(v), "corner": int(i), "column": int(c), "row": int(r), "residual_px": float(size),
                     "robust_sigmas": float(size / scale)})
    names = [_corner_words(h) for h in left[:6]]
    more = f" ... ({len(hits)} in all)" if len(hits) > 6 else ""
    df = fit.K[0, 0] - result.K[0, 0]
    return Finding(
        "outlier_corners", "doubtful",
        f"{len(hits)} corner(s) lie far from where the camera puts them ({'; '.join(names)}{more}; the limit is "
        f"{limit:.2f} px: {OUTLIER_CORNER_Z:g} x {scale:.3f} px, the residuals' robust sigma, and at least "
        f"{OUTLIER_CORNER_MIN_PX:g} px). Calibrated again without "
        f"{'it' if len(hits) == 1 else 'them'}: RMS {result.rms:.3f} -> {fit.rms:.3f} px, fx {df:+.2f} px",
        "use the calibration without these corners (shown above) or re-detect those views: a corner the "
        "detector put on clutter, a reflection or the board's edge", sorted({v for v, _, _ in hits})), fit, left


def _corner_words(h: dict) -> str:
    return (f"view {h['view']} corner {h['corner']} (column {h['column']}, row {h['row']}): {h['residual_px']:.2f} px, "
            f"{h['robust_sigmas']:.0f} sigma")


def leave_out_outlier_corners(result, evidence: Evidence):
    """``result`` calibrated again without its outlier corners (``left_out_corners`` names them), or ``result``.

    What ``dtscal calibrate-intrinsics`` and the live CALIBRATE do after dropping outlier views
    (:func:`dtscal_lib.session.calibrate_without_outlier_views`). Nothing is left out when the far-off corners
    are the echo of something else: a column or row offset in many views (:func:`_offset_findings`) or a lens the
    model cannot follow (a finer lens model, fitted, explains the residual: :func:`_fit_findings`).
    """
    obj = [np.asarray(o, float)[:, :2] for o in result.object_points]
    img = [np.asarray(p, float).reshape(-1, 2) for p in result.image_points]
    res = residuals(result)
    finding, fit, left = _outlier_corners(evidence.refit, result, obj, img, res)
    if fit is None:
        return result
    noise_raw, _ = corner_noise(obj, img)
    noise = max(noise_raw, NOISE_FLOOR_PX) if np.isfinite(noise_raw) else max(result.sigma, NOISE_FLOOR_PX)
    if (any(f.code == "fit" for f in _fit_findings(result, noise)[0])
            or _offset_findings(evidence.refit, result, obj, img, res, noise)):
        return result
    fit.left_out_corners = list(result.left_out_corners) + left
    return fit


def _neighbour_correlation(obj_list, res) -> float:
    """Mean normalised dot product of the residual vectors of grid-neighbouring corners (0 for noise)."""
    num = den = 0.0
    for views, _, g in _grid_groups(obj_list):
        e = np.stack([res[v] for v in views])  # (G, N, 2)
        lookup = {(int(a), int(b)): i for i, (a, b) in enumerate(g)}
        pairs = np.array([(i, j) for i, (a, b) in enumerate(g) for da, db in ((1, 0), (0, 1))
                          if (j := lookup.get((int(a + da), int(b + db)))) is not None], dtype=int).reshape(-1, 2)
        if len(pairs):
            ei, ej = e[:, pairs[:, 0]], e[:, pairs[:, 1]]
            num += float(np.einsum("vpc,vpc->", ei, ej))
            den += 0.5 * float(np.einsum("vpc,vpc->", ei, ei) + np.einsum("vpc,vpc->", ej, ej))
    return num / den if den > 0 else 0.0


def _list(views) -> str:
    views = [int(v) for v in views]
    return ", ".join(map(str, views[:12])) + (f" ... ({len(views)} in all)" if len(views) > 12 else "")


def assess(result, evidence: Evidence, *, uncertainty: bool = True, distance: float | None = None) -> Quality:
    """Judge a calibration: verdict (``good`` / ``doubtful`` / ``bad``), findings with advice, uncertainty.

    Parameters
    ----------
    result : CalibrationResult (it carries its views)
    uncertainty : also compute the projection-uncertainty map (a few hundred ms for 70 views)
    distance : distance of the fixed points of the uncertainty map (default: median board distance)

    Time and memory are linear in the views (4000 views of 35 corners: about 2 s and +89 MB on 2 busy cores).
    """
    try:
        return _assess(result, evidence, uncertainty=uncertainty, distance=distance)
    except MemoryError:
        raise CalibrationError(
            f"not enough memory to judge a calibration of {result.n_views} views ({result.n_points} corners, about "
            f"{result.n_points * 1.1e-6:.2f} GB needed); judge a calibration of fewer views") from None


def _assess(result, ev: Evidence, *, uncertainty: bool, distance: float | None) -> Quality:
    _need_observations(result)
    obj = [np.asarray(o, float)[:, :2] for o in result.object_points]
    img = [np.asarray(p, float).reshape(-1, 2) for p in result.image_points]
    res = residuals(result)
    noise_raw, n_noise = corner_noise(obj, img)
    noise = max(noise_raw, NOISE_FLOOR_PX) if np.isfinite(noise_raw) else max(result.sigma, NOISE_FLOOR_PX)
    findings: list[Finding] = []
    pv = np.asarray(result.per_view_rms)

    ratio = result.sigma / noise
    fit_findings, notes, richer_fits = _fit_findings(result, noise)
    findings += fit_findings

    limit = VIEW_OUTLIER_FACTOR * float(np.median(pv))
    bad_views = [int(v) for v in np.flatnonzero((pv > limit) & (pv / np.sqrt(2) > 2 * noise))]
    if bad_views:
        findings.append(Finding(
            "outlier_views", "doubtful",
            f"view(s) {_list(bad_views)} fit far worse than the others (RMS "
            f"{', '.join(f'{pv[v]:.2f}' for v in bad_views[:6])} px against a median of {np.median(pv):.3f} px)",
            f"drop view(s) {_list(bad_views)} (a wrong or blurred detection) and calibrate again", bad_views))

    line_findings = _offset_findings(ev.refit, result, obj, img, res, noise)
    findings += line_findings
    if line_findings:  # a bent column or row is the cause of the residual: the fit rule only echoes it
        for f in findings:
            if f.code == "unexplained_fit":
                f.severity, f.advice = "good", ""
                notes.append(f)
        findings = [f for f in findings if f.code != "unexplained_fit"]
    # a bad column or row also shows as radial and correlated residuals: report the cause, not its echoes
    radial = None if line_findings else _radial_finding(result, res, noise)
    if radial is not None:
        lens_words = _richer_model(result, noise, richer_fits)
        radial.advice = f"{lens_words}; {radial.advice}"
        if lens_words.startswith("not the lens model"):  # the finer models were fitted and do not remove it
            radial.message = radial.message.replace(
                f"a radial pattern the {result.model} distortion model cannot absorb",
                "a radial pattern that finer lens models fitted to the same corners do not remove (the print or "
                "the detector)")
        findings.append(radial)
    lens_blamed = any(f.code == "fit" for f in fit_findings)  # then far-off corners are the lens's echo
    corner_finding, without_corners, _ = ((None, None, []) if lens_blamed or line_findings
                                          else _outlier_corners(ev.refit, result, obj, img, res))
    left_out = list(getattr(result, "left_out_corners", []) or [])
    if corner_finding is None and left_out:
        corner_finding = Finding(
            "outlier_corners", "doubtful",
            f"{len(left_out)} corner(s) lay far from where the camera puts them and were left out before this "
            f"calibration ({'; '.join(_corner_words(h) for h in left_out[:6])}"
            f"{f' ... ({len(left_out)} in all)' if len(left_out) > 6 else ''})",
            "nothing to do for this calibration; re-detect those views or look at them: a corner the detector put "
            "on clutter, a reflection or the board's edge", sorted({h["view"] for h in left_out}))
    if corner_finding is not None:
        findings.append(corner_finding)
    rho = _neighbour_correlation(obj, res)
    if rho > NEIGHBOUR_CORRELATION and ratio > 1.2 and not line_findings and corner_finding is None:
        findings.append(Finding(
            # above 2x the noise the systematic part of the residual is larger than the noise itself
            # (sqrt(ratio^2 - 1) > 1.7): the parameters are biased far beyond their standard deviations
            "neighbour_correlation", "doubtful" if ratio <= SYSTEMATIC_RATIO_BAD else "bad",
            f"neighbouring corners share their error (correlation {rho:.2f} of adjacent residuals, 0 for noise) "
            f"and the residuals are {ratio:.1f} times the corner noise: a pattern the {result.model} model "
            "cannot absorb, which biases the parameters beyond their standard deviations",
            f"{_richer_model(result, noise, richer_fits)}; check that the board is flat and its squares are the "
            "size given"))

    if result.n_views < MIN_GOOD_VIEWS:
        findings.append(Finding(
            "few_views", "doubtful",
            f"only {result.n_views} views: too few to tell a wrong view from the rest",
            f"collect at least {MIN_GOOD_VIEWS} (better 20 or more) views at different places and tilts"))
    spread = ev.tilt_spread_deg
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
    umap = cov = None
    # the projection uncertainty propagates the kit's own solver's normal equations; OpenCV's models have none
    if uncertainty and result.model in KIT_SOLVER_MODELS and ev.blocks is not None:
        try:
            cov = _uncertainty_inputs(ev.blocks)
            umap = uncertainty_map(result, distance=distance, cov=cov)
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
    elif umap is not None and corner_severity(umap.corner_mean) != "good":
        findings.append(Finding(
            "uncertainty", corner_severity(umap.corner_mean),
            f"a pixel at the image corners can move by {umap.corner_mean:.2f} px (1 sigma) within the "
            "parameters' uncertainty",
            f"hold the board next in the {help_region} of the image (filling it, tilted), where the uncertainty "
            "is largest"))
    verdict = max((f.severity for f in findings), key=_SEVERITY.__getitem__, default="good")
    cons = None
    if umap is not None:
        try:
            cons = consequences(result, umap=umap, cov=cov)
        except (np.linalg.LinAlgError, DtscalError):
            cons = None
    if cons is not None:
        for n in notes + [f for f in findings if f.code in ("fit", "board_warp", "unexplained_fit")]:
            n.message += _ground_cost(result, noise, cons)  # what the residual above the noise costs on the ground
    return Quality(verdict, findings, float(noise), n_noise, float(result.sigma), pv, res, umap, counts,
                   help_region, spread, consequences=cons, notes=notes, without_outlier_corners=without_corners,
                   richer=richer_fits)


def corner_severity(corner_sigma_px: float) -> str:
    """The verdict of the mean 1-sigma projection uncertainty at the image corners (pixels)."""
    if corner_sigma_px > CORNER_SIGMA_BAD:
        return "bad"
    return "doubtful" if corner_sigma_px > CORNER_SIGMA_DOUBTFUL else "good"


def _ground_cost(result, noise, cons) -> str:
    """The residual that is not noise, carried onto the ground as the consequences' pixels are."""
    excess = float(np.sqrt(max(result.sigma ** 2 - noise ** 2, 0.0)))
    parts = [f"{100 * g['ahead_m']:.0f} cm ahead {excess * g['ground_sigma_cm'] / g['pixel_sigma_px']:.2g} cm"
             for g in cons["ground"] if g["ground_sigma_cm"] and g["pixel_sigma_px"]]
    if not parts:
        return ""
    return (f". On a Duckiebot a pixel error of that size moves a ground point {', '.join(parts)}")


# =========================================================================== what it means for a robot
def _nominal_camera() -> tuple[np.ndarray, np.ndarray]:
    """Rotation robot -> camera (3, 3) and camera centre (3,) of the nominal Duckiebot mounting."""
    th = np.radians(NOMINAL_CAMERA_PITCH_DEG)
    z = np.array([np.cos(th), 0.0, -np.sin(th)])  # optical axis, looking forward and down
    x = np.array([0.0, -1.0, 0.0])  # image right = robot's right
    return np.array([x, np.cross(z, x), z]), np.array([NOMINAL_CAMERA_X_M, 0.0, NOMINAL_CAMERA_HEIGHT_M])


def _pixel_to_ground(result, pix: np.ndarray) -> np.ndarray:
    """Ground points (M, 2) metres, robot frame, seen at ``pix`` through the nominal mounting."""
    R, c = _nominal_camera()
    d = _rays(result, pix) @ R  # ray directions in the robot frame
    return c[:2] + d[:, :2] * (-c[2] / d[:, 2:3])


def consequences(result, *, umap: UncertaintyMap | None = None, cov=None) -> dict:
    """What the calibration's uncertainty means for a Duckiebot's ground projection and image corners.

    The camera is put where a Duckiebot's is (:data:`NOMINAL_CAMERA_HEIGHT_M` above the ground,
    :data:`NOMINAL_CAMERA_PITCH_DEG` down, held fixed: only the intrinsics are in doubt). For each
    distance of :data:`CONSEQUENCE_DISTANCES_M` ahead of the axle, the ground point there is seen at a
    pixel; that pixel's 1-sigma projection uncertainty (:func:`projection_uncertainty`, the noise model
    covariance) is carried onto the ground through the mounting: ``ground_sigma_cm`` (worst direction)
    and ``forward_sigma_cm`` (along the robot's x). ``corner_sigma_px`` is the mean 1-sigma at the four
    image corners. ``relative_uncertainty`` is how uncertain these figures are themselves: a spread
    measured over V views is known to about ``1 / sqrt(2 (V - 1))`` of itself.
    """
    w, h = result.image_size
    Rc, c = _nominal_camera()
    cov = _uncertainty_inputs(result.normal_blocks()) if cov is None else cov
    out = []
    for x in CONSEQUENCE_DISTANCES_M:
        Pc = Rc @ (np.array([x, 0.0, 0.0]) - c)
        q = project_points(Pc[None], np.zeros(3), np.zeros(3), result.K, result.dist)[0]
        row = {"ahead_m": float(x), "pixel": [float(q[0]), float(q[1])],
               "in_image": bool(0 <= q[0] < w and 0 <= q[1] < h),
               "pixel_sigma_px": None, "ground_sigma_cm": None, "forward_sigma_cm": None}
        if row["in_image"]:
            Sq = projection_uncertainty(result, q[None], distance=float(np.linalg.norm(Pc)), cov=cov)[0]
            eps = 0.5
            J = np.column_stack([(_pixel_to_ground(result, (q + e)[None]) - _pixel_to_ground(result, (q - e)[None]))[0]
                                 / (2 * eps) for e in (np.array([eps, 0.0]), np.array([0.0, eps]))])
            Sg = J @ Sq @ J.T
            if np.all(np.isfinite(Sg)):
                row.update(pixel_sigma_px=float(worst_direction_sigma(Sq)),
                           ground_sigma_cm=100.0 * float(worst_direction_sigma(Sg)),
                           forward_sigma_cm=100.0 * float(np.sqrt(Sg[0, 0])))
        out.append(row)
    corner = None if umap is None or np.isnan(umap.corner_mean) else float(umap.corner_mean)
    return {"mounting": {"height_m": NOMINAL_CAMERA_HEIGHT_M, "pitch_down_deg": NOMINAL_CAMERA_PITCH_DEG,
                         "ahead_of_axle_m": NOMINAL_CAMERA_X_M},
            "ground": out, "corner_sigma_px": corner,
            "relative_uncertainty": float(1.0 / np.sqrt(2.0 * max(result.n_views - 1, 1))),
            "sigma_method": getattr(result, "std_method", "")}


_VERDICT_WORDS = {
    "good": "good: the model explains the corners down to their noise, and the data pin the camera down.",
    "doubtful": "doubtful: usable, but something in the data or the model is not what the noise model assumes "
                "(the findings say what); the uncertainties stated here include it.",
    "bad": "bad: do not use this calibration on a robot; the findings say what to change.",
}


def explain(q: Quality) -> str:
    """The verdict, why, and what it means for a Duckiebot, as a few sentences (:meth:`Quality.meaning`)."""
    lines = [f"Verdict {_VERDICT_WORDS[q.verdict]}"]
    codes = {f.code for f in q.findings}
    if codes & {"fit", "board_warp", "unexplained_fit"} or q.notes:
        ratio = q.fit_sigma / max(q.noise_sigma, NOISE_FLOOR_PX)
        lines.append(
            f"The residuals are {ratio:.1f}x the corner noise measured in these very images: part of every residual "
            "is not noise but a pattern shared by neighbouring corners. More views of the same kind do not average "
            "it away; the standard deviations of the parameters are therefore measured from how much the views "
            "disagree with each other, not from the noise alone.")
        lines += [n.message[:1].upper() + n.message[1:] + "." for n in q.notes]
    c = q.consequences
    if c:
        m = c["mounting"]
        parts = []
        for g in c["ground"]:
            if g["ground_sigma_cm"] is None:
                parts.append(f"{100 * g['ahead_m']:.0f} cm ahead is outside this camera's image")
            else:
                parts.append(f"a point {100 * g['ahead_m']:.0f} cm ahead is placed within "
                             f"+-{g['ground_sigma_cm']:.2g} cm (1 sigma; {g['pixel_sigma_px']:.2g} px in the image)")
        rel = 100 * c["relative_uncertainty"]
        corner = ("cannot be stated (the lens model folds over there)" if c["corner_sigma_px"] is None
                  else f"is uncertain by {c['corner_sigma_px']:.2f} px (1 sigma)")
        lines.append(
            f"On a Duckiebot (camera {100 * m['height_m']:.0f} cm above the ground, {m['pitch_down_deg']:.0f} degrees "
            f"down), ground projection through these intrinsics: {'; '.join(parts)}. A pixel at the image corners "
            f"{corner}. These figures are themselves known to about +-{rel:.0f} % (from {q.per_view_rms.size} views). "
            "Lane detection projects the pixels of the road's markings onto the ground, so a pixel's error becomes "
            "centimetres that grow with the distance; the extrapolated image corners are where a lane marking seen "
            "at the side of the image is placed worst, and where more views (boards held there) help most.")
    return " ".join(lines)


def monte_carlo_projection(result, pixels, refit, *, runs: int = 50, distance: float | None = None, seed: int = 0,
                           noise: float | None = None) -> np.ndarray:
    """Projections (runs, M, 2) of the fixed points seen at ``pixels``, re-calibrating on resampled noise.

    The check of :func:`projection_uncertainty` without linearisation: the solved camera and poses
    give perfect corners, Gaussian noise of ``noise`` px (default: the fit's ``sigma``) is added,
    the calibration is repeated (same model), and the same fixed 3-D points (held in the boards'
    frames, averaged over the boards) are projected with each run's intrinsics and poses. The
    spread over runs is what the uncertainty map predicts.
    """
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
    out = []
    for _ in range(runs):
        rr = refit(obj, [p + rng.normal(0.0, s, p.shape) for p in perfect])
        Pm = np.mean([X @ cv2.Rodrigues(r.reshape(3, 1))[0].T + t for X, r, t in zip(Xb, rr.rvecs, rr.tvecs)],
                     axis=0)
        out.append(project_points(Pm, np.zeros(3), np.zeros(3), rr.K, rr.dist))
    return np.array(out)
