"""Camera model: intrinsic matrix with skew, lens distortion, projection, rectification.

Conventions (activity text, eqs. (1)-(2)):

* A world point ``X`` (N, 3) is moved into the camera frame by ``Xc = R X + t``.
* Normalized coordinates are ``x = Xc / Zc`` (N, 2): the image of a unit-focal pinhole.
* Lens distortion maps normalized ``x`` to distorted normalized ``x_d`` (``plumb_bob``:
  OpenCV's 5-term model ``[k1, k2, p1, p2, k3]``; ``radial2``: Zhang's ``[k1, k2]``,
  stored as 5 values with zeros for p1, p2, k3).
* Pixels are ``[u, v, 1]^T = K [x_d, y_d, 1]^T`` with
  ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` (``s`` is the skew).

Where OpenCV defines the same thing (``projectPoints``, ``undistortPoints``,
``initUndistortRectifyMap``) these functions agree with it; unlike those OpenCV
functions they honour the skew ``s`` of ``K``. The undistortion here uses Newton's
method with the analytic Jacobian, so it converges over the whole image of a strongly
distorted wide lens (OpenCV's default fixed-point iteration stops after 5 rounds).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .errors import DtscalError

#: the distortion models of the kit (defined here only): OpenCV's 5-term ``plumb_bob``, Zhang's ``radial2``,
#: and ROS's two others (camera_calibration's calibrator.py): ``rational_polynomial`` (OpenCV's
#: CALIB_RATIONAL_MODEL, 8 coefficients ``[k1, k2, p1, p2, k3, k4, k5, k6]``) and ``equidistant`` (the fisheye
#: model of ``cv2.fisheye``, 4 coefficients ``[k1, k2, k3, k4]``)
DIST_MODELS = ("plumb_bob", "radial2", "rational_polynomial", "equidistant")
#: how many coefficients a model's ``dist`` (and its file's D) has: ROS's D lengths (5, 8 and 4)
MODEL_COEFFS = {"plumb_bob": 5, "radial2": 5, "rational_polynomial": 8, "equidistant": 4}
#: the models the kit's own solver calibrates; the others are calibrated by OpenCV (calibration.calibrate_opencv)
KIT_SOLVER_MODELS = ("plumb_bob", "radial2")


# --------------------------------------------------------------------------- input checks
def as_points(a, dim: int | tuple[int, ...], name: str, *, error: type[DtscalError] = DtscalError) -> np.ndarray:
    """The kit's one point-array validator: ``a`` as finite (N, dim) float64.

    A single point ``(dim,)`` and OpenCV's ``(N, 1, dim)`` are accepted. ``dim`` may be a
    tuple of allowed widths (e.g. ``(2, 3)``). Raises ``error`` (a :class:`DtscalError`)
    naming ``name`` and the shape it got.

    >>> as_points([1.0, 2.0], 2, "pixels").shape
    (1, 2)
    """
    dims = (dim,) if isinstance(dim, int) else tuple(dim)
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise error(f"{name} must be a numeric array, got {type(a).__name__}") from None
    if arr.ndim == 1 and arr.size in dims:
        arr = arr.reshape(1, arr.size)
    if arr.ndim == 3 and arr.shape[1] == 1:  # OpenCV's (N, 1, d)
        arr = arr.reshape(-1, arr.shape[2])
    if arr.ndim != 2 or arr.shape[1] not in dims:
        want = " or ".join(f"(N, {d})" for d in dims)
        raise error(f"{name} must have shape {want}, got {np.shape(a)}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.sum(~np.all(np.isfinite(arr), axis=1)))
        raise error(f"{name} contain NaN or infinite values ({bad} point(s)); remove them first")
    return arr


def as_K(K) -> np.ndarray:
    """Validate an intrinsic matrix: (3, 3) finite, upper triangular, positive focal lengths."""
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise DtscalError(f"K must be a 3x3 matrix, got shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise DtscalError("K contains NaN or infinite values")
    if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[2, 2] - 1) > 1e-12 or np.any(K[[1, 2, 2], [0, 0, 1]] != 0):
        raise DtscalError(
            "K must look like [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0; got\n" + str(K)
        )
    return K


def as_dist(dist) -> np.ndarray:
    """Distortion coefficients as 5 values ``[k1, k2, p1, p2, k3]``.

    Accepts 0 (no distortion), 2 (``radial2``: k1, k2), 4 (k1, k2, p1, p2) or 5 values;
    longer OpenCV vectors are accepted only if the extra terms are zero.
    """
    d = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    if not np.all(np.isfinite(d)):
        raise DtscalError("distortion coefficients contain NaN or infinite values")
    if d.size in (0, 2, 4, 5):
        out = np.zeros(5)
        out[: d.size] = d
        return out
    if d.size > 5 and not np.any(d[5:]):
        return d[:5].copy()
    raise DtscalError(
        f"expected 2, 4 or 5 distortion coefficients [k1, k2, p1, p2, k3], got {d.size}: {d}"
    )


def intrinsic_matrix(fx: float, fy: float, cx: float, cy: float, skew: float = 0.0) -> np.ndarray:
    """Build ``K = [[fx, skew, cx], [0, fy, cy], [0, 0, 1]]``, (3, 3) float64."""
    return as_K([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


# --------------------------------------------------------------------------- pixels <-> normalized
def normalized_to_pixel(xy, K) -> np.ndarray:
    """``[u, v] = K [x, y, 1]`` for (N, 2) normalized points; returns (N, 2) pixels."""
    xy = as_points(xy, 2, "normalized points")
    K = as_K(K)
    u = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
    v = K[1, 1] * xy[:, 1] + K[1, 2]
    return np.column_stack([u, v])


def pixel_to_normalized(uv, K) -> np.ndarray:
    """Inverse of :func:`normalized_to_pixel` (no distortion involved), (N, 2) -> (N, 2)."""
    uv = as_points(uv, 2, "pixels")
    K = as_K(K)
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    return np.column_stack([x, y])


# --------------------------------------------------------------------------- distortion
def distort_normalized(xy, dist) -> np.ndarray:
    """Apply plumb_bob lens distortion to normalized points.

    ``x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)``,
    ``y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y``.

    Parameters
    ----------
    xy : (N, 2) float64 normalized points
    dist : 2, 4 or 5 coefficients ``[k1, k2, p1, p2, k3]``

    Returns
    -------
    (N, 2) float64 distorted normalized points
    """
    xy = as_points(xy, 2, "normalized points")
    k1, k2, p1, p2, k3 = as_dist(dist)
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.column_stack([xd, yd])


def _distortion_jacobian(x, y, k1, k2, p1, p2, k3):
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)
    # d/dx and d/dy of r2 are 2x and 2y
    dxd_dx = radial + x * dradial_dr2 * 2.0 * x + 2.0 * p1 * y + p2 * 6.0 * x
    dxd_dy = x * dradial_dr2 * 2.0 * y + 2.0 * p1 * x + p2 * 2.0 * y
    dyd_dx = y * dradial_dr2 * 2.0 * x + p1 * 2.0 * x + 2.0 * p2 * y
    dyd_dy = radial + y * dradial_dr2 * 2.0 * y + p1 * 6.0 * y + 2.0 * p2 * x
    return dxd_dx, dxd_dy, dyd_dx, dyd_dy


def undistort_normalized(xy_d, dist, *, tol: float = 1e-14, max_iter: int = 50) -> np.ndarray:
    """Invert :func:`distort_normalized` by Newton's method.

    Solves ``distort_normalized(x) = x_d`` for every point independently, starting from
    ``x = x_d`` and using the analytic 2x2 Jacobian. On the Duckiebot's default lens
    (k1 = -0.257) it converges to better than 1e-12 over the whole 640x480 image in
    a handful of iterations.

    Parameters
    ----------
    xy_d : (N, 2) distorted normalized points
    dist : 2, 4 or 5 coefficients
    tol : stop when every residual ``|distort(x) - x_d|`` is below this
    max_iter : iteration cap

    Returns
    -------
    (N, 2) float64 undistorted normalized points

    Raises
    ------
    DtscalError
        If some point does not converge to 1e-9 (the distortion is not invertible there,
        e.g. a polynomial that folds back outside the lens's useful field).
    """
    xy_d = as_points(xy_d, 2, "distorted normalized points")
    d = as_dist(dist)
    if not np.any(d):
        return xy_d.copy()
    k1, k2, p1, p2, k3 = d
    out = xy_d.copy()
    # work on compact copies of the points still iterating; converged ones are written back
    idx = np.arange(len(out))
    x, y = out[:, 0].copy(), out[:, 1].copy()
    tx, ty = x.copy(), y.copy()
    for _ in range(max_iter):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        rx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - tx
        ry = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - ty
        done = np.maximum(np.abs(rx), np.abs(ry)) < tol
        if done.any():
            out[idx[done], 0], out[idx[done], 1] = x[done], y[done]
            keep = ~done
            idx, x, y, tx, ty, rx, ry = idx[keep], x[keep], y[keep], tx[keep], ty[keep], rx[keep], ry[keep]
            if len(idx) == 0:
                break
        a, b, c, e = _distortion_jacobian(x, y, k1, k2, p1, p2, k3)
        det = a * e - b * c
        det = np.where(np.abs(det) < 1e-300, 1e-300, det)
        x = x - (e * rx - b * ry) / det
        y = y - (-c * rx + a * ry) / det
    if len(idx):
        out[idx, 0], out[idx, 1] = x, y
        resid = np.abs(distort_normalized(out[idx], d) - xy_d[idx]).max(axis=1)
        if np.any(~np.isfinite(resid)) or resid.max() > 1e-9:
            raise DtscalError(
                f"undistortion did not converge for {int(np.sum(~(resid <= 1e-9)))} point(s) "
                f"(worst residual {np.nanmax(resid):.3g}); the distortion model is not invertible "
                "there. Check the distortion coefficients or restrict the points to the image."
            )
    return out


# --------------------------------------------------------------------------- every lens model
def as_model_dist(dist, model: str) -> np.ndarray:
    """``dist`` as the coefficient vector of ``model``: 5 (plumb_bob, radial2), 8 or 4 values.

    ``rational_polynomial`` accepts 5 (k4..k6 = 0), 8, or OpenCV's 12/14 with zeros past the 8th;
    ``equidistant`` exactly 4 (``cv2.fisheye``'s ``[k1, k2, k3, k4]``).
    """
    if model in ("plumb_bob", "radial2"):
        return as_dist(dist)
    if model not in MODEL_COEFFS:
        raise DtscalError(f"distortion model must be one of {DIST_MODELS}, got {model!r}")
    d = np.zeros(0) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    if not np.all(np.isfinite(d)):
        raise DtscalError("distortion coefficients contain NaN or infinite values")
    n = MODEL_COEFFS[model]
    if model == "rational_polynomial" and d.size in (0, 4, 5, 8):
        out = np.zeros(8)
        out[: d.size] = d
        return out
    if model == "rational_polynomial" and d.size > 8 and not np.any(d[8:]):
        return d[:8].copy()
    if model == "equidistant" and d.size in (0, 4):
        return np.zeros(4) if d.size == 0 else d.copy()
    names = "[k1, k2, p1, p2, k3, k4, k5, k6]" if model == "rational_polynomial" else "[k1, k2, k3, k4]"
    raise DtscalError(f"{model} needs {n} distortion coefficients {names}, got {d.size}: {d}")


def _theta_d(theta, k):
    t2 = theta * theta
    return theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))


def distort_model(xy, dist, model: str = "plumb_bob") -> np.ndarray:
    """Normalized points -> distorted normalized points under any of the kit's lens models.

    ``rational_polynomial`` (OpenCV's CALIB_RATIONAL_MODEL): the radial factor is
    ``(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)``, tangential terms as plumb_bob.
    ``equidistant`` (``cv2.fisheye``): ``theta = atan(r)``,
    ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``, ``x_d = theta_d / r x``.
    """
    if model in ("plumb_bob", "radial2"):
        return distort_normalized(xy, dist)
    xy = as_points(xy, 2, "normalized points")
    d = as_model_dist(dist, model)
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    if model == "rational_polynomial":
        k1, k2, p1, p2, k3, k4, k5, k6 = d
        radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return np.column_stack([xd, yd])
    r = np.sqrt(r2)
    theta = np.arctan(r)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(r > 1e-12, _theta_d(theta, d) / np.where(r > 1e-12, r, 1.0), 1.0)
    return xy * scale[:, None]


def undistort_model(xy_d, dist, model: str = "plumb_bob", *, strict: bool = True) -> np.ndarray:
    """Invert :func:`distort_model`. ``strict=False``: a point that does not converge is NaN instead of an error.

    plumb_bob: :func:`undistort_normalized` (Newton, analytic Jacobian). rational_polynomial: Newton with
    a central-difference Jacobian. equidistant: Newton on ``theta_d(theta)`` in one dimension, then
    ``r = tan(theta)`` (a ray beyond 90 degrees has no normalized point: NaN).
    """
    xy_d = as_points(xy_d, 2, "distorted normalized points")
    if model in ("plumb_bob", "radial2"):
        if strict:
            return undistort_normalized(xy_d, dist)
        out = np.full_like(xy_d, np.nan)
        try:
            return undistort_normalized(xy_d, dist)
        except DtscalError:  # some points fold over: solve them one by one, NaN where there is no inverse
            for i, p in enumerate(xy_d):
                try:
                    out[i] = undistort_normalized(p[None], dist)[0]
                except DtscalError:
                    pass
            return out
    d = as_model_dist(dist, model)
    if model == "equidistant":
        td = np.hypot(xy_d[:, 0], xy_d[:, 1])
        theta = np.clip(td, 0.0, np.pi / 2)
        for _ in range(50):
            t2 = theta * theta
            f = _theta_d(theta, d) - td
            df = 1.0 + t2 * (3 * d[0] + t2 * (5 * d[1] + t2 * (7 * d[2] + t2 * 9 * d[3])))
            step = f / np.where(np.abs(df) < 1e-300, 1e-300, df)
            theta = theta - step
            if np.all(np.abs(step) < 1e-15):
                break
        bad = ~(np.abs(_theta_d(theta, d) - td) <= 1e-9) | ~(theta < np.pi / 2) | ~(theta >= 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(td > 1e-12, np.tan(theta) / np.where(td > 1e-12, td, 1.0), 1.0)
        out = xy_d * scale[:, None]
    else:
        out = xy_d.copy()
        h = 1e-7
        for _ in range(60):
            f = distort_model(out, d, model) - xy_d
            if np.all(np.abs(f) < 1e-14):
                break
            fx1 = (distort_model(out + [h, 0], d, model) - distort_model(out - [h, 0], d, model)) / (2 * h)
            fy1 = (distort_model(out + [0, h], d, model) - distort_model(out - [0, h], d, model)) / (2 * h)
            a, c, b, e = fx1[:, 0], fx1[:, 1], fy1[:, 0], fy1[:, 1]
            det = a * e - b * c
            det = np.where(np.abs(det) < 1e-300, 1e-300, det)
            out = out - np.column_stack([(e * f[:, 0] - b * f[:, 1]) / det, (-c * f[:, 0] + a * f[:, 1]) / det])
            out[~np.isfinite(out)] = 0.0
        bad = ~(np.abs(distort_model(out, d, model) - xy_d).max(axis=1) <= 1e-9)
    if bad.any():
        if strict:
            raise DtscalError(
                f"undistortion did not converge for {int(bad.sum())} point(s) under the {model} model; the lens "
                "model is not invertible there. Check the distortion coefficients or restrict the points to the "
                "image.")
        out = out.copy()
        out[bad] = np.nan
    return out


def project_rays(rays, K, dist, model: str = "plumb_bob") -> np.ndarray:
    """Camera-frame points or ray directions (N, 3) -> pixels; NaN for a ray the model cannot image.

    A pinhole model (plumb_bob, rational) images rays in front of the camera (z > 0); equidistant
    images every ray within 90 degrees of the axis as well (theta from ``atan2(r, z)``).
    """
    P = as_points(rays, 3, "rays")
    K = as_K(K)
    out = np.full((len(P), 2), np.nan)
    if model == "equidistant":
        d = as_model_dist(dist, model)
        r = np.hypot(P[:, 0], P[:, 1])
        theta = np.arctan2(r, P[:, 2])
        ok = theta < np.pi / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(r > 1e-15, _theta_d(theta, d) / np.where(r > 1e-15, r, 1.0), 1.0 / np.where(
                P[:, 2] > 0, P[:, 2], 1.0))
        xy = P[:, :2] * s[:, None]
        if ok.any():
            out[ok] = normalized_to_pixel(xy[ok], K)
        return out
    ok = P[:, 2] > 0
    if ok.any():
        out[ok] = normalized_to_pixel(distort_model(P[ok, :2] / P[ok, 2:3], dist, model), K)
    return out


# --------------------------------------------------------------------------- 3-D projection
def as_rotation(r) -> np.ndarray:
    """A rotation given as a Rodrigues vector (3,) or a matrix (3, 3), as a (3, 3) matrix."""
    r = np.asarray(r, dtype=np.float64)
    if not np.all(np.isfinite(r)):
        raise DtscalError("the rotation contains NaN or infinite values")
    if r.size == 3:
        return cv2.Rodrigues(r.reshape(3, 1))[0]
    if r.shape == (3, 3):
        return r
    raise DtscalError(f"a rotation must be a Rodrigues vector (3,) or a 3x3 matrix, got shape {r.shape}")


def project_points(X, r, t, K, dist=None, *, model: str = "plumb_bob") -> np.ndarray:
    """Project world points into pixels (activity text, eqs. (1)-(2), plus lens distortion).

    Parameters
    ----------
    X : (N, 3) world points
    r : rotation, Rodrigues (3,) or matrix (3, 3), world -> camera
    t : (3,) translation, world -> camera
    K : (3, 3) intrinsic matrix (skew honoured)
    dist : distortion coefficients or None

    Returns
    -------
    (N, 2) float64 pixels. Points behind the camera raise an error.

    Examples
    --------
    >>> K = intrinsic_matrix(300, 300, 320, 240)
    >>> project_points([[0, 0, 1.0]], np.zeros(3), np.zeros(3), K)
    array([[320., 240.]])
    """
    X = as_points(X, 3, "world points")
    R = as_rotation(r)
    t = np.asarray(t, dtype=np.float64)
    if t.size != 3 or not np.all(np.isfinite(t)):
        raise DtscalError(f"the translation must be 3 finite values, got {t.ravel()!r}")
    t = t.reshape(3)
    Xc = X @ R.T + t
    if np.any(Xc[:, 2] <= 0):
        raise DtscalError(f"{int(np.sum(Xc[:, 2] <= 0))} point(s) are behind the camera (Z <= 0)")
    xy = Xc[:, :2] / Xc[:, 2:3]
    return normalized_to_pixel(distort_model(xy, dist, model), K)


def undistort_pixels(uv, K, dist, R=None, P=None, *, model: str = "plumb_bob") -> np.ndarray:
    """Like ``cv2.undistortPoints``: distorted pixels -> ideal points.

    Without ``P`` the result is normalized coordinates; with ``P`` (3, 3) or (3, 4) it is
    pixels of the rectified image (``P[:, :3]`` as its camera matrix). ``R`` (3, 3) is a
    rectification rotation applied in between (identity by default).
    """
    xy = undistort_model(pixel_to_normalized(uv, K), dist, model)
    if R is None and P is None:
        return xy
    rays = np.column_stack([xy, np.ones(len(xy))])
    if R is not None:
        rays = rays @ as_rotation(R).T
    if np.any(rays[:, 2] <= 0):
        raise DtscalError("the rectification rotation turns some points behind the camera")
    xy = rays[:, :2] / rays[:, 2:3]
    if P is None:
        return xy
    P = np.asarray(P, dtype=np.float64)
    return normalized_to_pixel(xy, as_K(P[:3, :3]))


# --------------------------------------------------------------------------- rectification
def new_camera_matrix(K, dist, size, alpha: float = 0.0, model: str = "plumb_bob") -> np.ndarray:
    """The rectified image's camera matrix, as ROS sets ``P``: ``cv2.getOptimalNewCameraMatrix``.

    ``alpha = 0`` keeps only valid pixels (no black border, some field of view lost);
    ``alpha = 1`` keeps every source pixel (black corners). OpenCV ignores the skew of K here.
    """
    K = as_K(K)
    w, h = as_size(size)
    if model == "equidistant":
        # as ROS's calibrator (camera_calibration calibrator.py, set_alpha for the fisheye model): K with the
        # focal lengths divided by 1 + alpha (it notes estimateNewCameraMatrixForUndistortRectify misbehaves)
        newK = K.copy()
        newK[0, 1] = 0.0
        newK[0, 0] /= 1.0 + float(alpha)
        newK[1, 1] /= 1.0 + float(alpha)
        return newK
    newK, _ = cv2.getOptimalNewCameraMatrix(K, as_model_dist(dist, model), (w, h), float(alpha), (w, h))
    return np.asarray(newK, dtype=np.float64)


def as_size(size, *, name: str = "size", error: type[DtscalError] = DtscalError) -> tuple[int, int]:
    """Validate an image size ``(width, height)`` of positive integers; raise ``error`` if not."""
    try:
        w, h = (int(s) for s in size)
    except Exception:
        raise error(f"{name} must be (width, height), e.g. (640, 480); got {size!r}") from None
    if w <= 0 or h <= 0:
        raise error(f"{name} must be positive (width, height), got {size!r}")
    return w, h


def rectification_maps(K, dist, new_K, size, R=None, *, dtype=np.float32, model: str = "plumb_bob"):
    """Pixel maps for ``cv2.remap`` that undistort (and optionally rotate) an image.

    For every pixel ``(u, v)`` of the rectified image (camera matrix ``new_K``, size
    ``(width, height)``), ``map_x[v, u], map_y[v, u]`` is where to sample the distorted
    source image: back-project with ``new_K``, rotate by ``R^-1``, distort, apply ``K``.
    Same result as ``cv2.initUndistortRectifyMap(K, dist, R, new_K, size, CV_32FC1)``
    (which ignores skew) to float32 resolution.

    Returns
    -------
    map_x, map_y : (height, width) arrays of ``dtype`` (float32 for ``cv2.remap``)
    """
    K = as_K(K)
    new_K = as_K(np.asarray(new_K, dtype=np.float64)[:3, :3])
    w, h = as_size(size)
    rows, cols = np.indices((h, w), dtype=np.float64)
    pix = np.stack([cols.ravel(), rows.ravel(), np.ones(rows.size)], axis=1)
    M = new_K if R is None else new_K @ as_rotation(R)
    rays = pix @ np.linalg.inv(M).T
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = rays[:, :2] / rays[:, 2:3]
    ok = np.all(np.isfinite(xy), axis=1) & (rays[:, 2] > 0)
    out = np.full((rows.size, 2), -1.0)
    out[ok] = normalized_to_pixel(distort_model(xy[ok], dist, model), K)
    return out[:, 0].reshape(h, w).astype(dtype), out[:, 1].reshape(h, w).astype(dtype)


def rectify_image(image: np.ndarray, maps, interpolation=cv2.INTER_LINEAR) -> np.ndarray:
    """``cv2.remap`` an image with maps from :func:`rectification_maps`."""
    map_x, map_y = maps
    if image is None or image.size == 0:
        raise DtscalError("cannot rectify an empty image")
    if image.shape[:2] != map_x.shape:
        # maps are for a fixed image size; sampling positions refer to the source size used
        # to calibrate, so a different-size frame would be silently wrong
        raise DtscalError(
            f"image is {image.shape[1]}x{image.shape[0]} but the maps were built for "
            f"{map_x.shape[1]}x{map_x.shape[0]}; resize the frame to the calibrated size first"
        )
    return cv2.remap(image, map_x, map_y, interpolation, borderMode=cv2.BORDER_CONSTANT)


# --------------------------------------------------------------------------- the model object
@dataclass(frozen=True)
class CameraModel:
    """An intrinsically calibrated camera: ``K``, distortion, image size: the kit's one camera type.

    A calibration file's content (:class:`~dtscal_lib.calib_files.IntrinsicCalibration`) is
    this camera with a name and a rectification rotation; a calibration's result gives one
    with :meth:`~dtscal_lib.calibration.CalibrationResult.camera`.

    ``P`` is the rectified camera matrix ``[K' | 0]`` (3, 4) as ROS stores it; when not
    given it is computed with ``alpha = 0``, as ROS's calibrator does.

    Examples
    --------
    >>> from dtscal_lib import duckietown as dt
    >>> cam = CameraModel(dt.default_K(), dt.default_dist(), dt.IMAGE_SIZE)
    >>> cam.rectified_K.shape
    (3, 3)
    """

    K: np.ndarray
    dist: np.ndarray
    size: tuple[int, int]
    model: str = "plumb_bob"
    P: np.ndarray | None = field(default=None)

    def __post_init__(self):
        if self.model not in DIST_MODELS:
            raise DtscalError(f"distortion model must be one of {DIST_MODELS}, got {self.model!r}")
        object.__setattr__(self, "K", as_K(self.K).copy())
        object.__setattr__(self, "dist", as_model_dist(self.dist, self.model))
        object.__setattr__(self, "size", as_size(self.size))
        if self.P is None:
            P = np.zeros((3, 4))
            P[:, :3] = new_camera_matrix(self.K, self.dist, self.size, 0.0, self.model)
        else:
            P = np.asarray(self.P, dtype=np.float64)
            if P.shape == (3, 3):
                P = np.column_stack([P, np.zeros(3)])
            if P.shape != (3, 4) or not np.all(np.isfinite(P)):
                raise DtscalError(f"P must be a finite 3x4 matrix, got shape {P.shape}")
        object.__setattr__(self, "P", P)

    @property
    def rectified_K(self) -> np.ndarray:
        return self.P[:, :3].copy()

    def project(self, X, r, t) -> np.ndarray:
        return project_points(X, r, t, self.K, self.dist, model=self.model)

    def undistort_pixels(self, uv, rectified: bool = True) -> np.ndarray:
        """Distorted pixels -> rectified pixels (``rectified=True``) or normalized coordinates."""
        return undistort_pixels(uv, self.K, self.dist, P=self.P if rectified else None, model=self.model)

    def rectification_maps(self, new_K=None, size=None):
        return rectification_maps(self.K, self.dist, self.rectified_K if new_K is None else new_K,
                                  self.size if size is None else size, model=self.model)

    def opencv_maps(self, R=None):
        """OpenCV's rectification maps for this camera (float32): ``cv2.initUndistortRectifyMap``, or
        ``cv2.fisheye.initUndistortRectifyMap`` for the equidistant model (OpenCV ignores skew)."""
        R = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
        if self.model == "equidistant":
            return cv2.fisheye.initUndistortRectifyMap(self.K, self.dist.reshape(4, 1), R, self.rectified_K,
                                                       self.size, cv2.CV_32FC1)
        return cv2.initUndistortRectifyMap(self.K, self.dist, R, self.rectified_K, self.size, cv2.CV_32FC1)

    def with_alpha(self, alpha: float) -> "CameraModel":
        """The same camera with ``P`` recomputed for another ``alpha`` (0 = crop, 1 = keep all)."""
        P = np.zeros((3, 4))
        P[:, :3] = new_camera_matrix(self.K, self.dist, self.size, alpha, self.model)
        return CameraModel(self.K, self.dist, self.size, self.model, P)
