"""The one home of the plane homography: estimate, apply, invert, measure.

A homography maps points of one plane to another, ``[u, v, w]^T = H [x, y, 1]^T`` and then
``(u / w, v / w)`` (activity text, eq. (6)). The kit meets it three times: a board view
(board metres -> pixels, the raw material of Zhang's method), the ground (rectified pixels ->
metres on the road, the Duckiebot's extrinsic calibration) and the course figures. All of them
use this module.

:func:`estimate_homography` is the normalized direct linear transform (Hartley's
normalization, then the singular vector of the smallest singular value). The course's
notebook 02 asks students to write the same algorithm; the library needs it for calibration's
closed-form start, so it holds its own vectorized version (the README's section on honest
separation says why, and which other exercise computations the library contains).

Examples
--------
>>> import numpy as np
>>> H = np.array([[1.2, 0.1, 30.0], [-0.05, 0.9, 12.0], [1e-4, 2e-4, 1.0]])
>>> src = np.array([[0.0, 0], [100, 0], [100, 80], [0, 80], [50, 30]])
>>> dst = apply_homography(H, src)
>>> bool(np.allclose(estimate_homography(src, dst), H))
True
>>> bool(np.allclose(apply_homography(invert_homography(H), dst), src))
True
>>> float(transfer_error(H, src, dst).max()) < 1e-9
True
"""

from __future__ import annotations

import numpy as np

from .camera import as_points
from .errors import DtscalError

__all__ = ["as_homography", "normalizer", "estimate_homography", "apply_homography", "invert_homography",
           "transfer_error", "transfer_rms"]


def as_homography(H, name: str = "H") -> np.ndarray:
    """``H`` as a finite (3, 3) float64 array (9 row-major values are accepted too)."""
    try:
        arr = np.asarray(H, dtype=np.float64)
    except (TypeError, ValueError):
        raise DtscalError(f"{name} must be a 3x3 numeric matrix, got {type(H).__name__}") from None
    if arr.size != 9:
        raise DtscalError(f"{name} must be a 3x3 homography (or 9 row-major values), got shape {arr.shape}")
    arr = arr.reshape(3, 3)
    if not np.all(np.isfinite(arr)):
        raise DtscalError(f"{name} contains NaN or infinite values")
    return arr


def normalizer(points: np.ndarray) -> np.ndarray:
    """Hartley's conditioning matrix (3, 3) for (N, 2) points: centroid to 0, mean distance sqrt(2).

    >>> normalizer(np.array([[0.0, 0.0], [2.0, 0.0]]))[0].round(4).tolist()
    [1.4142, 0.0, -1.4142]
    """
    p = np.asarray(points, dtype=np.float64)
    c = p.mean(axis=0)
    d = np.sqrt(((p - c) ** 2).sum(axis=1)).mean()
    if not d > 0:
        raise DtscalError("all points are in one spot; a homography needs points that span an area")
    s = np.sqrt(2.0) / d
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def estimate_homography(src, dst) -> np.ndarray:
    """The homography mapping ``src`` to ``dst``, by the normalized DLT.

    Both point sets are conditioned (:func:`normalizer`); each pair gives the two rows of
    ``A h = 0`` obtained by cross-multiplying eq. (6) of the activity text; ``h`` is the right singular vector
    of the smallest singular value; the conditioning is undone, ``H = T_dst^-1 H~ T_src``.
    The DLT minimizes an algebraic error; for the geometric (pixel) error refine it, as
    ``cv2.findHomography`` does.

    Parameters
    ----------
    src : (N, 2) float64 source points, N >= 4, not all on one line
    dst : (N, 2) float64 destination points

    Returns
    -------
    (3, 3) float64 ``H`` scaled so ``H[2, 2] = 1`` (unit Frobenius norm when ``H[2, 2]`` is 0)

    Raises
    ------
    DtscalError
        Fewer than 4 pairs, unequal counts, or points in one spot.
    """
    a = as_points(src, 2, "source points")
    b = as_points(dst, 2, "destination points")
    if len(a) != len(b):
        raise DtscalError(f"got {len(a)} source points but {len(b)} destination points; they must pair up")
    if len(a) < 4:
        raise DtscalError(f"a homography needs at least 4 point pairs, got {len(a)}")
    Ta, Tb = normalizer(a), normalizer(b)
    a = a @ Ta[:2, :2].T + Ta[:2, 2]
    b = b @ Tb[:2, :2].T + Tb[:2, 2]
    n = len(a)
    A = np.zeros((2 * n, 9))
    A[0::2, 0:2], A[0::2, 2] = a, 1.0
    A[0::2, 6:8], A[0::2, 8] = -b[:, :1] * a, -b[:, 0]
    A[1::2, 3:5], A[1::2, 5] = a, 1.0
    A[1::2, 6:8], A[1::2, 8] = -b[:, 1:2] * a, -b[:, 1]
    Hn = np.linalg.svd(A, full_matrices=len(A) < 9)[2][-1].reshape(3, 3)
    H = np.linalg.solve(Tb, Hn @ Ta)
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 * np.abs(H).max() else H / np.linalg.norm(H)


def apply_homography(H, pts) -> np.ndarray:
    """Map points with a homography: ``[x, y, w]^T = H [u, v, 1]^T``, then ``(x / w, y / w)``.

    Parameters
    ----------
    H : (3, 3) homography
    pts : (N, 2) points (or a single (2,) point)

    Returns
    -------
    (N, 2) float64 mapped points

    Raises
    ------
    DtscalError
        If a point maps to infinity (``w = 0``: for a ground homography, a pixel on the
        horizon line).
    """
    H = as_homography(H)
    pts = as_points(pts, 2, "points")
    hom = pts @ H[:, :2].T + H[:, 2]
    scale = np.abs(pts[:, 0] * H[2, 0]) + np.abs(pts[:, 1] * H[2, 1]) + abs(H[2, 2])
    w = hom[:, 2]
    bad = np.abs(w) <= 1e-12 * scale
    if np.any(bad):
        raise DtscalError(
            f"{int(bad.sum())} point(s) map to infinity under the homography (e.g. {pts[bad][0].tolist()}); "
            "for a ground homography these pixels lie on the horizon, not on the ground"
        )
    return hom[:, :2] / w[:, None]


def invert_homography(H) -> np.ndarray:
    """``H^-1`` scaled so its ``[2, 2]`` entry is 1 (when it is not 0).

    Raises
    ------
    DtscalError
        If ``H`` is singular (it maps the plane onto a line).
    """
    H = as_homography(H)
    sv = np.linalg.svd(H, compute_uv=False)
    if not sv[-1] > 1e-14 * sv[0]:
        raise DtscalError("the homography is singular and cannot be inverted; fit it again from points that "
                          "span an area")
    Hinv = np.linalg.inv(H)
    return Hinv / Hinv[2, 2] if abs(Hinv[2, 2]) > 1e-12 * np.abs(Hinv).max() else Hinv


def transfer_error(H, src, dst) -> np.ndarray:
    """Per pair, the distance ``|H(src) - dst|`` in destination units, (N,) float64."""
    d = as_points(dst, 2, "destination points")
    return np.linalg.norm(apply_homography(H, src) - d, axis=1)


def transfer_rms(H, src, dst) -> float:
    """Root mean square of :func:`transfer_error`."""
    e = transfer_error(H, src, dst)
    return float(np.sqrt(np.mean(e ** 2)))
