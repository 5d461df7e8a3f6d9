# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: paper_given_svd_closed
# formulation: H as given (Zhang's paper), SVD, closed form; lambda = 1 / |K^-1 h1|
import math

import numpy as np


def intrinsic_constraints(H):
    H = np.asarray(H, dtype=np.float64)

    def v(i, j):
        a, b = H[:, i], H[:, j]
        return np.array([a[0] * b[0], a[0] * b[1] + a[1] * b[0], a[1] * b[1],
                         a[2] * b[0] + a[0] * b[2], a[2] * b[1] + a[1] * b[2], a[2] * b[2]])

    return np.vstack([v(0, 1), v(0, 0) - v(1, 1)])


def intrinsics_from_homographies(Hs):
    Hs = [np.asarray(H, dtype=np.float64) for H in Hs]
    if len(Hs) < 3:
        raise ValueError(f"need at least 3 views, got {len(Hs)}")
    V = np.vstack([intrinsic_constraints(H) for H in Hs])
    pass
    b = np.linalg.svd(V)[2][-1]
    B11, B12, B22, B13, B23, B33 = b
    cy = (B12 * B13 - B11 * B23) / (B11 * B22 - B12 ** 2)
    lam = B33 - (B13 ** 2 + cy * (B12 * B13 - B11 * B23)) / B11
    fx = math.sqrt(lam / B11)
    fy = math.sqrt(lam * B11 / (B11 * B22 - B12 ** 2))
    s = -B12 * fx ** 2 * fy / lam
    cx = s * cy / fy - B13 * fx ** 2 / lam
    return np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def extrinsics_from_homography(K, H):
    A = np.linalg.inv(np.asarray(K, float)) @ np.asarray(H, float)
    lam = 1.0 / np.linalg.norm(A[:, 0])
    if A[2, 2] < 0:
        lam = -lam
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return R, t
