"""Zhang's closed form: the homography of every view, the constraints on ``B = K^-T K^-1``, K and the poses.

The start of :func:`dtscal_lib.calibration.calibrate` (steps 2-4 of its docstring): one normalized DLT per
view, Zhang's two constraints per view (activity text, eqs. (12)-(13)) on image-normalized homographies,
``K`` from ``B`` (Zhang's appendix B, skew included) and each view's ``[r1 r2 t]`` from ``K^-1 H``; the
degeneracy check that stops before garbage is optimised, and the boards' tilt spread.
"""

from __future__ import annotations

import cv2
import numpy as np

from .errors import CalibrationError
from .homography import estimate_homography

__all__ = ["plane_homography", "zhang_closed_form", "board_normal_spread"]

#: relative singular value below which the stacked Zhang constraints count as rank deficient
_PARALLEL_VIEWS_TOL = 2e-3


def plane_homography(plane_points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Normalized DLT homography from board-plane points to pixels.

    The kit's one implementation is :func:`dtscal_lib.homography.estimate_homography`.
    """
    return estimate_homography(plane_points, pixels)


def _null_vector(A: np.ndarray) -> np.ndarray:
    """Unit right singular vector of the smallest singular value of ``A`` (m, n).

    Only the thin SVD is computed when ``m >= n``: the full one would build an
    (m, m) matrix of left singular vectors, quadratic in the number of views or points.
    """
    return np.linalg.svd(A, full_matrices=A.shape[0] < A.shape[1])[2][-1]


def _v_row(H: np.ndarray, i: int, j: int) -> np.ndarray:
    """Zhang's ``v_ij`` with ``h_i^T B h_j = v_ij . b`` for ``b = (B11, B12, B22, B13, B23, B33)``."""
    # h_i^T B h_j = sum_kl B_kl (h_i h_j^T)_kl; off-diagonal entries of the symmetric B
    # collect both (k, l) and (l, k)
    outer = np.outer(H[:, i], H[:, j])
    sym = outer + outer.T
    return np.array([outer[0, 0], sym[0, 1], outer[1, 1], sym[0, 2], sym[1, 2], outer[2, 2]])


def _image_normalizer(size: tuple[int, int]) -> np.ndarray:
    """Pixels -> roughly unit coordinates (centre at 0, scale ``(w + h) / 2``) for conditioning."""
    w, h = size
    f = (w + h) / 2.0
    return np.array([[1.0 / f, 0.0, -(w - 1) / 2.0 / f], [0.0, 1.0 / f, -(h - 1) / 2.0 / f], [0.0, 0.0, 1.0]])


def _constraint_matrix(homographies, size, skew: bool) -> np.ndarray:
    """Stacked Zhang constraints (12)-(13) for homographies in image-normalized coordinates.

    Each row is scaled to unit norm so that views weigh alike; without skew the row
    ``B12 = 0`` is appended.
    """
    T = _image_normalizer(size)
    rows = []
    for H in homographies:
        Hn = T @ H
        Hn = Hn / np.sqrt(np.linalg.norm(Hn[:, 0]) * np.linalg.norm(Hn[:, 1]))
        for r in (_v_row(Hn, 0, 1), _v_row(Hn, 0, 0) - _v_row(Hn, 1, 1)):
            rows.append(r / np.linalg.norm(r))
    if not skew:
        rows.append(np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]))
    return np.array(rows)


def _check_not_degenerate(V: np.ndarray, n_views: int, skew: bool) -> None:
    """Raise if the constraints leave more than a one-dimensional family of ``b``."""
    s = np.linalg.svd(V, compute_uv=False)
    ratio = s[4] / s[0]
    if ratio < _PARALLEL_VIEWS_TOL:
        need = "at least 3 board orientations" if skew else "at least 2 clearly different board orientations"
        raise CalibrationError(
            f"the {n_views} views do not constrain the intrinsics: the boards are (nearly) parallel "
            f"to each other (Zhang's constraint matrix is rank deficient, relative singular value "
            f"{ratio:.2g}). Shifting or turning the board in its own plane adds nothing; tilt it "
            f"left/right and up/down by 20-45 degrees to get {need}."
        )


def _intrinsics_from_b(b: np.ndarray) -> np.ndarray | None:
    """Zhang's appendix B: ``K`` from ``b`` (up to scale); ``None`` if not physical."""
    if b[0] < 0:
        b = -b
    B11, B12, B22, B13, B23, B33 = b
    den = B11 * B22 - B12 * B12
    if B11 <= 0 or den <= 0:
        return None
    v0 = (B12 * B13 - B11 * B23) / den
    lam = B33 - (B13 * B13 + v0 * (B12 * B13 - B11 * B23)) / B11
    if lam <= 0:
        return None
    alpha = np.sqrt(lam / B11)
    beta = np.sqrt(lam * B11 / den)
    gamma = -B12 * alpha * alpha * beta / lam
    u0 = gamma * v0 / beta - B13 * alpha * alpha / lam
    K = np.array([[alpha, gamma, u0], [0.0, beta, v0], [0.0, 0.0, 1.0]])
    return K if np.all(np.isfinite(K)) else None


def zhang_closed_form(homographies, image_size, *, skew: bool = True) -> np.ndarray | None:
    """Zhang's closed-form intrinsics from plane-to-image homographies.

    Solves ``V b = 0`` (activity text, eqs. (12)-(13) of every view, stacked), ``b`` the
    upper triangle of ``B = K^-T K^-1``, in image-normalized coordinates for
    conditioning, then reads ``K`` off ``B``.

    Parameters
    ----------
    homographies : sequence of (3, 3) board-plane -> pixel homographies
    image_size : (width, height), only used for conditioning
    skew : estimate the skew (else ``B12 = 0`` is imposed)

    Returns
    -------
    (3, 3) float64 K, or ``None`` when the solution is not physical (``B`` not
    positive definite: noise, strong distortion or nearly degenerate views).
    """
    size = (int(image_size[0]), int(image_size[1]))
    V = _constraint_matrix(homographies, size, skew)
    b = _null_vector(V)
    Kn = _intrinsics_from_b(b)
    if Kn is None:
        return None
    K = np.linalg.solve(_image_normalizer(size), Kn)  # K = T^-1 Kn
    K = K / K[2, 2]
    if not skew:
        K[0, 1] = 0.0
    return K


def _pose_from_homography(H: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Board pose ``(rvec, t)`` from ``H ~ K [r1 r2 t]``; rotation made orthonormal by SVD."""
    M = np.linalg.solve(K, H)
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    if M[2, 2] * lam < 0:  # the board must be in front of the camera
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Wt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1.0, 1.0, -1.0]) @ Wt
    return cv2.Rodrigues(R)[0].ravel(), t


def board_normal_spread(rvecs) -> float:
    """Largest angle (degrees) between a board normal and the mean normal of all views.

    Parameters
    ----------
    rvecs : (V, 3) Rodrigues vectors, board -> camera

    Returns
    -------
    float, degrees; 0 when every board is parallel to every other.
    """
    rv = np.asarray(rvecs, dtype=np.float64).reshape(-1, 3)
    normals = np.array([cv2.Rodrigues(r.reshape(3, 1))[0][:, 2] for r in rv])
    normals *= np.where(normals[:, 2:3] < 0, -1.0, 1.0)  # one side of the board
    mean = normals.mean(axis=0)
    mean /= np.linalg.norm(mean)
    return float(np.degrees(np.arccos(np.clip(normals @ mean, -1.0, 1.0))).max())


