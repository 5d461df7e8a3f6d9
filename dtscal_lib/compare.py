"""How different are two intrinsic calibrations of one camera? The projection difference over the image.

The question a TA asks when a student re-calibrates: does the new file change what the robot sees? Two
calibrations of the same lens are compared the way mrcal does it (``mrcal.projection_diff``,
``mrcal-show-projection-diff``, mrcal's model_analysis.py; mrcal.secretsauce.net/differencing.html):

1. grid the image (``gridn_width`` points across, mrcal's ``sample_imager``: from pixel 0 to W-1 and
   H-1, ``gridn_height = round(H / W gridn_width)``);
2. unproject every grid pixel with each model, giving two unit rays ``v0`` (model A) and ``v1`` (model B);
3. fit the rotation ``R`` that best lines up A's rays with B's (the two calibrations' camera frames float
   with respect to the housing: a different ``cx`` is partly a small rotation); with mrcal's cost at
   infinity, ``sum_i (w_i th_i^2)^2`` with ``th_i^2 = 2 (1 - <R v0_i, v1_i>)`` and a Huber loss of scale
   (5 degrees)^2, over the pixels within ``focus_radius`` of the centre (``min(W, H) / 6`` when no
   uncertainty is known) or over the whole image weighted by ``w = 1 / (sigma_A sigma_B)^2`` when both
   calibrations' projection uncertainties are known;
4. project ``R v0`` with model B: the difference to the grid pixel is the projection difference.

Points at infinity (rotation only) are what mrcal uses by default; both models' rays then differ only
through their intrinsics and the one rotation. Where a model cannot unproject a pixel (a polynomial that
folds over near a corner) the difference is NaN there and counted.

The difference is judged against the calibrations' own uncertainty when known (a
:class:`~dtscal_lib.calibration.CalibrationResult` carries it, and so does a file the kit wrote, in its extra key
``dtscal_uncertainty``, :mod:`dtscal_lib.file_uncertainty`; a ROS file has no field for it): the
difference of two independent calibrations has a 1-sigma spread of ``sqrt(sigma_A^2 + sigma_B^2)``
per pixel (worst direction, :func:`dtscal_lib.quality.projection_uncertainty` at infinity).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from .camera import CameraModel, pixel_to_normalized, project_rays, undistort_model
from . import safe_write
from .errors import DtscalError

#: mrcal's default grid (``projection_diff(gridn_width=60)``)
GRIDN_WIDTH = 60
#: mrcal's Huber scale of the rotation fit, degrees (``implied_Rt10__from_unprojections``: f_scale_deg = 5)
HUBER_DEG = 5.0
#: where the summary reads the difference: the image centre and its four corners
PLACES = ("centre", "top-left", "top-right", "bottom-left", "bottom-right")
#: "within its uncertainty": the largest difference over the image (where both are known) at most this many
#: combined sigmas; 2 sigma covers 95 % of a normal spread (the kit's usual two-sided bound)
WITHIN_SIGMAS = 2.0


def as_camera(obj) -> CameraModel:
    """A camera from a :class:`CameraModel` (a calibration file's content is one), a calibration result
    (``.camera()``), or a file path."""
    if isinstance(obj, CameraModel):
        return obj
    if hasattr(obj, "camera") and callable(obj.camera):
        return obj.camera()
    from .calib_files import load_intrinsics

    return load_intrinsics(obj)


def grid(size, gridn_width: int = GRIDN_WIDTH, gridn_height: int | None = None) -> np.ndarray:
    """mrcal's ``sample_imager``: (gridn_height, gridn_width, 2) pixels from (0, 0) to (W-1, H-1)."""
    w, h = size
    if gridn_height is None:
        gridn_height = int(round(h / w * gridn_width))
    if gridn_width < 2 or gridn_height < 2:
        raise DtscalError(f"the grid needs at least 2x2 points, got {gridn_width}x{gridn_height}")
    u, v = np.meshgrid(np.linspace(0, w - 1, gridn_width), np.linspace(0, h - 1, gridn_height))
    return np.stack([u, v], axis=-1)


def unproject(cam: CameraModel, pixels) -> np.ndarray:
    """Unit rays (N, 3) of distorted pixels under ``cam``'s model; NaN where the model has no inverse."""
    xy = undistort_model(pixel_to_normalized(pixels, cam.K), cam.dist, cam.model, strict=False)
    rays = np.column_stack([xy, np.ones(len(xy))])
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def _rodrigues(r: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(r))
    if th < 1e-300:
        return np.eye(3)
    k = r / th
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * Kx + (1 - np.cos(th)) * Kx @ Kx


def fit_rotation(v0: np.ndarray, v1: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """The rotation ``R`` (3, 3) minimising mrcal's ``sum (w th^2)^2`` (Huber, 5 degrees), ``th`` the angle
    between ``R v0_i`` and ``v1_i``. Started from the weighted Procrustes solution (Wahba's problem, SVD),
    refined as mrcal refines it (scipy's least_squares, dogbox, Huber loss)."""
    w = np.ones(len(v0)) if weights is None else np.asarray(weights, dtype=np.float64)
    ok = np.all(np.isfinite(v0), axis=1) & np.all(np.isfinite(v1), axis=1) & np.isfinite(w) & (w > 0)
    if ok.sum() < 3:
        raise DtscalError("too few pixels where both calibrations can unproject to fit the aligning rotation")
    v0, v1, w = v0[ok], v1[ok], w[ok]
    B = (v1 * w[:, None]).T @ v0
    U, _, Vt = np.linalg.svd(B)
    R0 = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt

    def residual(r):
        p = v0 @ (_rodrigues(r) @ R0).T
        return w * 2.0 * (1.0 - np.sum(p * v1, axis=1))  # mrcal's residual: w th^2

    def jacobian(r):
        # R -> exp([dr]_x) R moves p to p + dr x p, so d<p, v1>/d dr = p x v1 (exact at the current r up to
        # the exponential map's first order, which dogbox's trust region absorbs)
        p = v0 @ (_rodrigues(r) @ R0).T
        return -2.0 * w[:, None] * np.cross(p, v1)

    # mrcal's solve (implied_Rt10__from_unprojections at infinity): dogbox, Huber of scale (5 deg)^2, the
    # gradient test effectively disabled so that nearly identical models still converge
    res = least_squares(residual, np.zeros(3), jac=jacobian, method="dogbox", loss="huber",
                        f_scale=np.deg2rad(HUBER_DEG) ** 2, gtol=np.finfo(float).eps)
    return _rodrigues(res.x) @ R0


@dataclass
class Comparison:
    """The projection difference of calibration B against calibration A over A's image grid.

    ``diff`` (gridn_height, gridn_width) pixels (NaN where a model cannot unproject); ``pixels`` the grid;
    ``rotation`` the aligning rotation (A's camera frame -> B's) and its angle; ``at`` the difference at
    :data:`PLACES`; ``sigma`` the combined 1-sigma of the difference (same shape as ``diff``) when both
    uncertainties are known, else None; ``focus_radius`` the fit's region (inf: the whole image, weighted).
    """

    pixels: np.ndarray
    diff: np.ndarray
    rotation: np.ndarray
    focus_radius: float
    sigma: np.ndarray | None = None
    names: tuple[str, str] = ("A", "B")
    at: dict = field(default_factory=dict)
    #: why a calibration's uncertainty is not known (one sentence each; empty when both are)
    unknown: list = field(default_factory=list)
    #: the two cameras compared (A, B)
    cameras: tuple = ()

    def __post_init__(self):
        h, w = self.diff.shape
        idx = {"centre": None, "top-left": (0, 0), "top-right": (0, w - 1), "bottom-left": (h - 1, 0),
               "bottom-right": (h - 1, w - 1)}
        for name, ij in idx.items():
            if ij is None:  # the grid point nearest the image centre
                c = self.pixels[..., :].reshape(-1, 2)
                cen = c.max(axis=0) / 2
                ij = np.unravel_index(int(np.argmin(np.linalg.norm(c - cen, axis=1))), (h, w))
            d = float(self.diff[ij])
            s = None if self.sigma is None else float(self.sigma[ij])
            self.at[name] = {"pixel": [float(v) for v in self.pixels[ij]], "diff_px": d, "sigma_px": s,
                             "ratio": None if s is None else d / s}

    @property
    def rotation_deg(self) -> float:
        R = self.rotation  # atan2 of sin and cos: precise at small angles, where arccos of the trace is not
        sin = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
        return float(np.degrees(np.arctan2(sin, (np.trace(R) - 1) / 2)))

    @property
    def n_unprojectable(self) -> int:
        return int(np.sum(~np.isfinite(self.diff)))

    @property
    def max_px(self) -> float:
        return float(np.nanmax(self.diff)) if np.isfinite(self.diff).any() else float("nan")

    @property
    def rms_px(self) -> float:
        return float(np.sqrt(np.nanmean(self.diff ** 2)))

    @property
    def max_ratio(self) -> float | None:
        if self.sigma is None:
            return None
        r = self.diff / self.sigma
        return float(np.nanmax(r)) if np.isfinite(r).any() else None

    @property
    def within(self) -> bool | None:
        """Whether B differs from A by at most :data:`WITHIN_SIGMAS` of their combined uncertainty everywhere."""
        m = self.max_ratio
        return None if m is None else bool(m <= WITHIN_SIGMAS)

    def sentence(self, other: str = "the robot's file") -> str:
        """One sentence for the notebook: how far the new calibration is from ``other``, and what COMMIT changes."""
        text = f"differs from {other} by at most {self.max_px:.1f} px"
        if self.n_unprojectable:
            text += f" (where both can unproject; {self.n_unprojectable} grid points cannot)"
        if self.within is None:
            why = "; ".join(self.unknown)
            return text + f" (RMS {self.rms_px:.1f} px; no uncertainty known to judge it against" + \
                (f": {why})" if why else ")")
        if self.within:
            return text + ", within its uncertainty: COMMIT changes little"
        return (text + f", {self.max_ratio:.1f}x its uncertainty: COMMIT changes what the robot sees; "
                       "the robot's file may be out of date (or this calibration poor: check the verdict)")

    def to_dict(self) -> dict:
        return {"a": self.names[0], "b": self.names[1], "max_px": self.max_px, "rms_px": self.rms_px,
                "rotation_deg": self.rotation_deg, "focus_radius": self.focus_radius,
                "grid": [int(self.diff.shape[1]), int(self.diff.shape[0])], "unprojectable": self.n_unprojectable,
                "at": self.at, "max_ratio": self.max_ratio, "within_uncertainty": self.within,
                "within_sigmas": WITHIN_SIGMAS, "uncertainty_unknown": list(self.unknown)}


def _sigma_of(source, pixels: np.ndarray, camera: CameraModel | None = None,
              unknown: list | None = None) -> np.ndarray | None:
    """Worst-direction 1-sigma projection uncertainty at ``pixels`` (points at infinity), or None (and the
    sentence why appended to ``unknown``). ``source`` a calibration result, a callable, or the path of a file
    (its ``dtscal_uncertainty``; ``camera`` its content)."""
    if source is None:
        return None
    if callable(source) and not hasattr(source, "camera"):
        return np.asarray(source(pixels), dtype=np.float64)
    if isinstance(source, (str, os.PathLike)):
        from .file_uncertainty import load

        unc, why = load(source, camera)
        if unc is None:
            if unknown is not None:
                unknown.append(why)
            return None
        return unc.projection_sigma(camera if camera is not None else as_camera(source), pixels)
    if hasattr(source, "normal_blocks") and getattr(source, "object_points", None):
        from .quality import projection_uncertainty, worst_direction_sigma

        # the parameters' honest covariance (the larger of the noise model and the views' disagreement,
        # :meth:`CalibrationResult.intrinsic_covariance`), not the noise model alone that the verdict's
        # image-corner figure shares with mrcal: two calibrations of one camera from different views differ by
        # what the views disagree on (on data/real 1.3-2.6x the noise model, docs/uncertainty.md), and "within its
        # uncertainty" must not call that a change of the camera
        cov = (source.normal_blocks(), source.intrinsic_covariance())
        return worst_direction_sigma(projection_uncertainty(source, pixels, distance=np.inf, cov=cov,
                                                            dist_idx=source.dist_indices))
    if unknown is not None:
        unknown.append(f"{getattr(source, 'camera_name', type(source).__name__)} was given without its file or "
                       "views, so its uncertainty is not known")
    return None


def projection_difference(a, b, *, gridn_width: int = GRIDN_WIDTH, gridn_height: int | None = None,
                          focus_radius: float | None = None, uncertainty: bool = True,
                          names: tuple[str, str] = ("A", "B")) -> Comparison:
    """Compare calibration ``b`` with ``a`` (each a camera, a calibration result or a file path).

    With ``uncertainty`` and ``a`` and ``b`` calibration results that carry their views, or paths of files that
    carry their σ (:mod:`dtscal_lib.file_uncertainty`), the rotation is
    fitted over the whole image weighted by ``1 / (sigma_a sigma_b)^2`` (mrcal's default) and the difference
    is judged against ``sqrt(sigma_a^2 + sigma_b^2)``; with one of them a result and the other a file, against
    the result's own sigma (the file's taken as equal to it in the weights); with neither, the fit uses the
    pixels within ``focus_radius`` (default ``min(W, H) / 6``, mrcal's) of the centre.
    """
    ca, cb = as_camera(a), as_camera(b)
    if tuple(ca.size) != tuple(cb.size):
        raise DtscalError(f"the two calibrations are for different image sizes ({ca.size[0]}x{ca.size[1]} and "
                          f"{cb.size[0]}x{cb.size[1]}); compare calibrations of the same camera mode")
    q0 = grid(ca.size, gridn_width, gridn_height)
    flat = q0.reshape(-1, 2)
    v0, v1 = unproject(ca, flat), unproject(cb, flat)
    unknown: list[str] = []
    sa = _sigma_of(a, flat, ca, unknown) if uncertainty else None
    sb = _sigma_of(b, flat, cb, unknown) if uncertainty else None
    w, h = ca.size
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    if sa is not None or sb is not None:
        # mrcal's weights 1 / (sigma_a sigma_b)^2; with one calibration's sigma only (a new calibration against
        # a file), the other is taken as equal to it
        s0 = sa if sa is not None else sb
        s1 = sb if sb is not None else sa
        weights = (1.0 / (s0 * s1)) ** 2
        radius = float("inf") if focus_radius is None else float(focus_radius)
    else:
        weights = np.ones(len(flat))
        radius = min(w, h) / 6.0 if focus_radius is None else float(focus_radius)
    weights = np.where(np.linalg.norm(flat - centre, axis=1) < radius, weights, 0.0)
    R = fit_rotation(v0, v1, weights)
    rays = v0 @ R.T
    fin = np.all(np.isfinite(rays), axis=1)  # a pixel A cannot unproject has no difference
    q1 = np.full_like(flat, np.nan)
    if fin.any():
        q1[fin] = project_rays(rays[fin], cb.K, cb.dist, cb.model)
    diff = np.linalg.norm(q1 - flat, axis=1).reshape(q0.shape[:2])
    # the 1-sigma of the difference: both calibrations' when both are known, else the one known (a file carries
    # none: the difference is then judged against the new calibration's own uncertainty)
    known = [x for x in (sa, sb) if x is not None]
    sigma = np.sqrt(sum(x ** 2 for x in known)).reshape(q0.shape[:2]) if known else None
    return Comparison(q0, diff, R, radius, sigma, names, unknown=unknown, cameras=(ca, cb))


def write_figure(comp: Comparison, path) -> None:
    """A heat map of the difference (pixels) over the image, with the values at the corners and centre."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    extent = (float(comp.pixels[..., 0].min()), float(comp.pixels[..., 0].max()), float(comp.pixels[..., 1].max()),
              float(comp.pixels[..., 1].min()))
    im = ax.imshow(comp.diff, extent=extent, cmap="viridis", vmin=0, vmax=np.nanpercentile(comp.diff, 99))
    fig.colorbar(im, ax=ax, label="projection difference (px)")
    for name, v in comp.at.items():
        ax.annotate(f"{v['diff_px']:.2f}", v["pixel"], color="white", fontsize=9, ha="center")
    ax.set_title(f"{comp.names[1]} vs {comp.names[0]}: max {comp.max_px:.2f} px, rotation {comp.rotation_deg:.3f} deg")
    fig.tight_layout()
    suffix = os.path.splitext(str(path))[1] or ".png"
    with safe_write.output(path, what="comparison figure", suffix=suffix) as tmp:
        fig.savefig(tmp, dpi=90, format=suffix.lstrip("."))
    plt.close(fig)


# --------------------------------------------------------------------------- cross-validation
#: how many random half splits ``--cross-validate`` makes by default, and the seed of the first
CROSS_VALIDATE_SPLITS = 5
CROSS_VALIDATE_SEED = 0


def half_splits(n_views: int, splits: int = CROSS_VALIDATE_SPLITS, seed: int = CROSS_VALIDATE_SEED):
    """``splits`` seeded random splits of ``n_views`` views into two halves (sorted index lists)."""
    if n_views < 6:
        raise DtscalError(f"cross-validation splits the views in two halves of at least 3 (a calibration's "
                          f"minimum); {n_views} views are too few: collect at least 6")
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(int(splits)):
        perm = rng.permutation(n_views)
        out.append((sorted(perm[: n_views // 2].tolist()), sorted(perm[n_views // 2:].tolist())))
    return out


def _inside(pixels: np.ndarray, size) -> np.ndarray:
    """Grid points of the central two thirds of the image (a sixth of each side left out)."""
    w, h = size
    u, v = pixels[..., 0], pixels[..., 1]
    return (u >= w / 6) & (u <= w - 1 - w / 6) & (v >= h / 6) & (v <= h - 1 - h / 6)


@dataclass
class CrossValidation:
    """Half-set calibrations against each other, judged by their predicted uncertainty.

    For each split: ``corners`` the largest difference / sigma at the four image corners, ``inside`` the
    largest over the central two thirds of the image (NaN where a half cannot unproject). A calibration whose
    predicted uncertainty is honest gives ratios of about 1 (the difference of two independent estimates is
    within 2 sigma 95 % of the time).
    """

    splits: list
    comparisons: list
    size: tuple[int, int]

    def ratios(self) -> list[dict]:
        out = []
        for c in self.comparisons:
            r = c.diff / c.sigma
            corner = [c.at[p]["ratio"] for p in PLACES[1:]]
            inner = r[_inside(c.pixels, self.size)]
            out.append({"corners": float(np.nanmax(corner)) if np.isfinite(corner).any() else float("nan"),
                        "inside": float(np.nanmax(inner)) if np.isfinite(inner).any() else float("nan"),
                        "max_px": c.max_px})
        return out

    def finding(self, limit: float | None = None):
        """A :class:`~dtscal_lib.findings.Finding` when the halves differ by more than their uncertainty says
        (``doubtful``: the stated sigma is too small or the model does not fit the lens), else None."""
        from .findings import Finding
        from .limits import CROSS_VALIDATION_RATIO

        limit = CROSS_VALIDATION_RATIO if limit is None else limit
        r = self.ratios()
        inside = float(np.nanmedian([x["inside"] for x in r]))
        corners = float(np.nanmedian([x["corners"] for x in r]))
        if not (inside > limit):
            return None
        return Finding(
            "cross_validation", "doubtful",
            f"calibrations of two halves of the views differ by {inside:.1f} times their predicted uncertainty "
            f"inside the image (median of {len(r)} random splits; {corners:.1f} at the corners): the stated "
            "sigma is too small for these views, or the lens model does not fit",
            "collect more views covering the whole image, or try a richer lens model (--model)")

    def to_dict(self) -> dict:
        return {"splits": [[list(map(int, a)), list(map(int, b))] for a, b in self.splits],
                "ratios": self.ratios()}


def cross_validate(object_points, image_points, image_size, *, model: str = "plumb_bob", skew: bool = False,
                   splits: int = CROSS_VALIDATE_SPLITS, seed: int = CROSS_VALIDATE_SEED) -> CrossValidation:
    """Calibrate random halves of the views and compare each pair against their predicted uncertainty.

    The kit's own solver (plumb_bob, radial2) only: OpenCV's models carry no projection uncertainty.
    """
    from .calibration import calibrate

    if model not in ("plumb_bob", "radial2"):
        raise DtscalError(f"--cross-validate needs the calibrations' projection uncertainty, which the kit computes "
                          f"for its own solver's models (plumb_bob, radial2), not for {model}")
    halves = half_splits(len(object_points), splits, seed)
    comps = []
    for a, b in halves:
        ra = calibrate([object_points[i] for i in a], [image_points[i] for i in a], image_size, model=model,
                       skew=skew)
        rb = calibrate([object_points[i] for i in b], [image_points[i] for i in b], image_size, model=model,
                       skew=skew)
        comps.append(projection_difference(ra, rb, names=("half A", "half B")))
    return CrossValidation(halves, comps, tuple(image_size))
