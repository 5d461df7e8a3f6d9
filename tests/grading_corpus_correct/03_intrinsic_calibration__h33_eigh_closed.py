# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: h33_eigh_closed
# formulation: H / H[2, 2], eigh of V^T V, closed form; lambda from the mean
import math

import numpy as np


def intrinsic_constraints(H):
    H = np.asarray(H, dtype=np.float64)
    rows = []
    for a, b in ((0, 1), (0, 0), (1, 1)):
        rows.append([])
        for i, j in ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)):
            E = np.zeros((3, 3))
            E[i, j] = E[j, i] = 1.0
            rows[-1].append(H[:, a] @ E @ H[:, b])
    r = np.array(rows)
    return np.vstack([r[0], r[1] - r[2]])


def intrinsics_from_homographies(Hs):
    Hs = [np.asarray(H, dtype=np.float64) for H in Hs]
    if len(Hs) < 3:
        raise ValueError(f"need at least 3 views, got {len(Hs)}")
    V = np.vstack([intrinsic_constraints(H / H[2, 2]) for H in Hs])
    pass
    b = np.linalg.eigh(V.T @ V)[1][:, 0]
    B11, B12, B22, B13, B23, B33 = b
    cy = (B12 * B13 - B11 * B23) / (B11 * B22 - B12 ** 2)
    lam = B33 - (B13 ** 2 + cy * (B12 * B13 - B11 * B23)) / B11
    fx = math.sqrt(lam / B11)
    fy = math.sqrt(lam * B11 / (B11 * B22 - B12 ** 2))
    s = -B12 * fx ** 2 * fy / lam
    cx = s * cy / fy - B13 * fx ** 2 / lam
    return np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


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
