"""The result of a calibration, and what the judge needs from it (:func:`evidence`).

:class:`CalibrationResult` is what :func:`dtscal_lib.calibration.calibrate` returns: the camera, the
poses, the residuals' size, the standard deviations and the views it was fitted to. :func:`evidence`
gathers what the verdict (:func:`dtscal_lib.quality.assess`) needs from the estimator -- the normal
equations at the solution, the estimated distortion terms, the boards' tilt spread and a way to
calibrate other views the same way -- so that the judge never calls back into the estimator: the
session computes the evidence, then asks the judge (``tests/test_session.py`` traces it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from . import lsq
from .camera import KIT_SOLVER_MODELS, CameraModel
from .closed_form import board_normal_spread
from .covariance import NormalBlocks, honest_intrinsic_covariance
from .errors import CalibrationError
from .findings import Evidence

__all__ = ["CalibrationResult", "evidence"]


@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate`.

    Attributes
    ----------
    K : (3, 3) float64 intrinsic matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``
    dist : (5,) float64 ``[k1, k2, p1, p2, k3]``; zeros for terms the model does not estimate
    rms : float, pixels: ``sqrt(sum over points of |reprojection residual|^2 / N)``,
        as ``cv2.calibrateCamera`` reports it (a residual is a 2-D vector)
    per_view_rms : (V,) float64 pixels, the same per view
    rvecs, tvecs : (V, 3) float64, board -> camera (Rodrigues vector, translation in
        the object points' unit)
    std : standard deviation of every estimated intrinsic parameter, keyed
        ``fx, fy, cx, cy, [skew], k1, k2, [p1, p2, [k3]]``: how far it would move, 1 sigma, if the
        calibration were repeated with new views of the same kind. The larger of the corner-noise
        model's and a sandwich over the views, close to a jackknife (:mod:`dtscal_lib.covariance`;
        ``std_method`` says which applied): residuals that are not independent noise make it larger
    std_noise_model : the same from the noise model alone, ``sigma^2 (J^T J)^-1`` (OpenCV's
        ``stdDeviationsIntrinsics``)
    model : ``"plumb_bob"`` or ``"radial2"``
    skew : whether the skew ``s = K[0, 1]`` was estimated
    image_size : (width, height)
    n_views, n_points : number of views and of points over all views
    """

    K: np.ndarray
    dist: np.ndarray
    rms: float
    per_view_rms: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    std: dict[str, float]
    model: str
    skew: bool
    image_size: tuple[int, int]
    n_views: int
    n_points: int
    #: ``sigma`` of the residual per coordinate, ``sqrt(|e|^2 / (2N - p))``, pixels
    sigma: float = field(default=float("nan"))
    #: Levenberg-Marquardt iterations used
    iterations: int = 0
    #: the refinement stopped on its own criteria (a step too small to matter, no decrease left), not at its cap
    #: (:data:`dtscal_lib.lsq.MAX_ITERATIONS`); the verdict calls a result that did not converge bad
    converged: bool = True
    #: the views the result was fitted to, (N_i, 2) board-plane points and (N_i, 2) pixels, for
    #: :meth:`quality` (residuals, verdict, projection uncertainty)
    object_points: list = field(default_factory=list, repr=False)
    image_points: list = field(default_factory=list, repr=False)
    #: standard deviations from the corner-noise model alone (see ``std``)
    std_noise_model: dict = field(default_factory=dict)
    #: how ``std`` (and the projection uncertainty) were computed, in words
    std_method: str = ""
    #: (n, n) covariance of the intrinsics in the order of ``std`` (the one ``std`` is the diagonal of)
    covariance: np.ndarray | None = field(default=None, repr=False)
    #: single corners left out as outliers before this fit (:func:`dtscal_lib.quality.leave_out_outlier_corners`),
    #: each ``{"view", "corner", "column", "row", "residual_px", "robust_sigmas"}`` (corner: its index in the view
    #: as detected); the views' points here no longer hold them
    left_out_corners: list = field(default_factory=list)

    def quality(self, **kw):
        """The verdict (:func:`dtscal_lib.quality.assess`) given what it needs (:func:`evidence`): the same two
        steps as the session's verdict (:meth:`dtscal_lib.session.IntrinsicSession.quality`)."""
        from .quality import assess

        return assess(self, evidence(self), **kw)

    # ------------------------------------------------------------------ what the judge needs
    @property
    def dist_indices(self) -> list[int]:
        """Indices into ``[k1, k2, p1, p2, k3]`` of the estimated distortion terms."""
        return lsq.dist_indices(self.model, self.std)

    def intrinsic_vector(self) -> np.ndarray:
        """The estimated intrinsics ``[fx, fy, cx, cy, (skew), dist...]`` in the order of ``std``."""
        K, di = self.K, self.dist_indices
        return np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], [K[0, 1]] if self.skew else [],
                               np.asarray(self.dist)[di]])

    def normal_blocks(self) -> NormalBlocks:
        """The normal equations at the solution, block by block (:class:`~dtscal_lib.covariance.NormalBlocks`)."""
        _need_views(self)
        return lsq.normal_blocks(self)

    def intrinsic_covariance(self) -> np.ndarray:
        """(n, n) covariance of the intrinsics (``covariance``, recomputed if the result was built without it)."""
        if self.covariance is None:
            self.covariance = honest_intrinsic_covariance(self.normal_blocks())[0]
        return self.covariance

    def without_outlier_corners(self) -> "CalibrationResult":
        """This calibration repeated without its single far-off corners, which ``left_out_corners`` then names
        (:func:`dtscal_lib.quality.leave_out_outlier_corners`); itself when there is none."""
        from .quality import leave_out_outlier_corners

        return leave_out_outlier_corners(self, evidence(self, blocks=False))

    def refit(self, object_points, image_points) -> "CalibrationResult":
        """:func:`~dtscal_lib.calibration.calibrate` other views with this result's model, skew and k3 choice."""
        return _refitter(self)(object_points, image_points)

    def board_normal_spread(self) -> float:
        """Largest angle (degrees) between a board normal and the mean normal: :func:`board_normal_spread`."""
        return board_normal_spread(self.rvecs)

    def camera(self) -> CameraModel:
        """The calibrated camera, with ``P`` from ``alpha = 0`` as ROS's calibrator sets it."""
        return CameraModel(self.K, self.dist, self.image_size, self.model)

    def to_dict(self) -> dict:
        """A JSON-serialisable summary (plain lists, floats, ints, strings)."""
        return {
            "model": self.model,
            "skew_estimated": bool(self.skew),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "K": [[float(v) for v in row] for row in np.asarray(self.K)],
            "dist": [float(v) for v in np.asarray(self.dist).ravel()],
            "rms": float(self.rms),
            "sigma": float(self.sigma),
            "per_view_rms": [float(v) for v in self.per_view_rms],
            "std": {k: float(v) for k, v in self.std.items()},
            "std_noise_model": {k: float(v) for k, v in self.std_noise_model.items()},
            "std_method": self.std_method,
            "rvecs": [[float(v) for v in r] for r in self.rvecs],
            "tvecs": [[float(v) for v in t] for t in self.tvecs],
            "n_views": int(self.n_views),
            "n_points": int(self.n_points),
            "iterations": int(self.iterations),
            "left_out_corners": [dict(c) for c in self.left_out_corners],
        }


def _need_views(result) -> None:
    if not result.object_points or len(result.object_points) != result.n_views:
        raise CalibrationError("this calibration result does not carry its views (object_points, image_points); "
                               "recompute it with dtscal_lib.calibration.calibrate to judge its quality")


def _refitter(result):
    """:func:`~dtscal_lib.calibration.calibrate` with ``result``'s image size, model, skew and k3 choice."""
    from .calibration import calibrate

    return partial(calibrate, image_size=result.image_size, model=result.model, skew=result.skew,
                   fix_k3="k3" not in result.std)


def evidence(result, *, blocks: bool = True) -> Evidence:
    """What the judge needs from the estimator, computed here so that it never calls back
    (:class:`~dtscal_lib.findings.Evidence`). ``blocks=False`` leaves out the normal equations (only the
    projection uncertainty needs them); OpenCV's models have none."""
    _need_views(result)
    nb = lsq.normal_blocks(result) if blocks and result.model in KIT_SOLVER_MODELS else None
    return Evidence(blocks=nb, dist_indices=lsq.dist_indices(result.model, result.std),
                    tilt_spread_deg=board_normal_spread(result.rvecs), refit=_refitter(result))
