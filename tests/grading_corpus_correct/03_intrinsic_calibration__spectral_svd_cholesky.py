# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: spectral_svd_cholesky
# formulation: H / spectral norm, SVD, Cholesky of B; lambda from the geometric mean
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
    V = np.vstack([intrinsic_constraints(H / np.linalg.norm(H, 2)) for H in Hs])
    pass
    b = np.linalg.svd(V)[2][-1]
    B11, B12, B22, B13, B23, B33 = b
    B = np.array([[B11, B12, B13], [B12, B22, B23], [B13, B23, B33]])
    if B[0, 0] < 0:
        B = -B
    L = np.linalg.cholesky(B)
    K = np.linalg.inv(L.T)
    return K / K[2, 2]


def extrinsics_from_homography(K, H):
    A = np.linalg.solve(np.asarray(K, float), np.asarray(H, float))
    lam = 1.0 / math.sqrt(np.linalg.norm(A[:, 0]) * np.linalg.norm(A[:, 1]))
    t = lam * A[:, 2]
    if t[2] < 0:
        lam, t = -lam, -t
    r1, r2 = lam * A[:, 0], lam * A[:, 1]
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    return U @ D @ Vt, t
