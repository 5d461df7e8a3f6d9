# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: frobenius_eigh_cholesky
# formulation: H / Frobenius norm, eigh of V^T V, Cholesky of B
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
    V = np.vstack([intrinsic_constraints(H / np.linalg.norm(H)) for H in Hs])
    pass
    b = np.linalg.eigh(V.T @ V)[1][:, 0]
    B11, B12, B22, B13, B23, B33 = b
    B = np.array([[B11, B12, B13], [B12, B22, B23], [B13, B23, B33]])
    if B[0, 0] < 0:
        B = -B
    L = np.linalg.cholesky(B)
    K = np.linalg.inv(L.T)
    return K / K[2, 2]


def extrinsics_from_homography(K, H):
    A = np.linalg.solve(np.asarray(K, dtype=np.float64), np.asarray(H, dtype=np.float64))
    lam = 2.0 / (np.linalg.norm(A[:, 0]) + np.linalg.norm(A[:, 1]))
    lam = math.copysign(lam, A[2, 2])
    Q = np.column_stack([lam * A[:, 0], lam * A[:, 1], np.cross(lam * A[:, 0], lam * A[:, 1])])
    U, _, Vt = np.linalg.svd(Q)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1, 1, -1]) @ Vt
    return R, lam * A[:, 2]
