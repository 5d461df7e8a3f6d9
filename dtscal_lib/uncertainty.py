"""The projection uncertainty over the image (mrcal's uncertainty maps), and what it means for a robot.

:func:`projection_uncertainty` propagates the parameters' covariance to the projection of fixed 3-D
points, as mrcal's ``projection_uncertainty`` does; :func:`uncertainty_map` grids it over the image;
:func:`consequences` carries it onto a Duckiebot's ground; :func:`robot_view` says where the robot looks
(a Duckiebot: the lower half of the image, the ground ahead; the DD24: its whole, downward view), which is
where the verdict's "bad" is measured (:mod:`dtscal_lib.rules`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera import pixel_to_normalized, project_points, undistort_model
from .covariance import projection_covariance, rodrigues
from .errors import CalibrationError
from .lsq import dist_indices as _lsq_dist_indices

__all__ = ["UncertaintyMap", "projection_uncertainty", "worst_direction_sigma", "uncertainty_map", "image_region",
           "consequences", "monte_carlo_projection", "robot_view", "REGION_NAMES", "CONSEQUENCE_DISTANCES_M"]


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


def _dist_idx(fit) -> list[int]:
    """The distortion terms a fit estimated (indices into ``[k1, k2, p1, p2, k3]``)."""
    return _lsq_dist_indices(getattr(fit, "model", "plumb_bob"), fit.std)


def _need_observations(result) -> None:
    if not getattr(result, "object_points", None) or len(result.object_points) != result.n_views:
        raise CalibrationError("this calibration result does not carry its views (object_points, image_points); "
                               "recompute it with dtscal_lib.calibration.calibrate to judge its quality")


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


def projection_uncertainty(result, pixels, *, distance: float | None = None, cov=None,
                           dist_idx: list[int] | None = None) -> np.ndarray:
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
    _, dqdP, dqdI = _projection_jacobian(P, result.K, result.dist, result.skew,
                                          _dist_idx(result) if dist_idx is None else dist_idx)
    omegas = pose_omegas(result.rvecs)
    with np.errstate(invalid="ignore"):  # NaN rays (a lens model that cannot be inverted) stay NaN
        return projection_covariance(blocks, cov_i, dqdI, dqdP, P, omegas,
                                     None if at_infinity else np.asarray(result.tvecs, dtype=np.float64))


def pose_omegas(rvecs) -> np.ndarray:
    """``W_v`` (V, 3, 3) of :func:`~dtscal_lib.covariance.projection_covariance`: column k the axis of the
    cross-product matrix ``dR_v/dr_k R_v^T`` of each board's rotation."""
    R0, dR0 = rodrigues(rvecs)
    W = np.einsum("vkij,vlj->vkil", dR0, R0)  # dR/dr_k R^T, a cross-product matrix [w_k]_x
    return np.stack([W[:, :, 2, 1], W[:, :, 0, 2], W[:, :, 1, 0]], axis=1)  # (V, 3 axis, 3 k)


def worst_direction_sigma(cov: np.ndarray) -> np.ndarray:
    """sqrt of the largest eigenvalue of each (2, 2) covariance: (M,) pixels."""
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    return np.sqrt(0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b ** 2))


def uncertainty_map(result, *, step: int = 20, distance: float | None = None, cov=None,
                    dist_idx: list[int] | None = None) -> UncertaintyMap:
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
    s = worst_direction_sigma(projection_uncertainty(result, np.vstack([grid, corners]), distance=d, cov=cov,
                                                        dist_idx=dist_idx))
    return UncertaintyMap(u, v, s[:-4].reshape(len(v), len(u)), corners, s[-4:], d)


def image_region(pixels, image_size) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) in 0..2 of the ninth of the image each pixel lies in."""
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    w, h = image_size
    return (np.clip((p[:, 1] * 3 // h).astype(int), 0, 2), np.clip((p[:, 0] * 3 // w).astype(int), 0, 2))


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


def consequences(result, *, umap: UncertaintyMap | None = None, cov=None, dist_idx: list[int] | None = None) -> dict:
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
            Sq = projection_uncertainty(result, q[None], distance=float(np.linalg.norm(Pc)), cov=cov,
                                        dist_idx=dist_idx)[0]
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



def robot_view(pixels, image_size) -> np.ndarray:
    """(M,) bool: the pixels where the robot looks, on whose projection it acts.

    A Duckiebot (landscape frames): the lower half of the image, the ground ahead where lane detection
    projects the road's markings (the nominal mounting puts the horizon near the top third: 25 degrees down
    with a vertical field of view of about 70 degrees). The DD24 (portrait frames,
    :func:`dtscal_lib.profiles.profile_for_image`): its whole view, pointed down at the ground below it.
    """
    p = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    w, h = image_size
    if h > w:  # the DD24's portrait camera
        return np.ones(len(p), dtype=bool)
    return p[:, 1] >= 0.5 * h


def robot_view_sigma(umap: UncertaintyMap, image_size) -> float:
    """Mean 1-sigma projection uncertainty (worst direction, pixels) over the map's pixels in :func:`robot_view`."""
    grid = np.column_stack([np.tile(umap.u, len(umap.v)), np.repeat(umap.v, len(umap.u))])
    vals = umap.sigma.ravel()[robot_view(grid, image_size)]
    return float(np.mean(vals)) if len(vals) else float("nan")
