# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: rows_normalized
# formulation: rows of V normalized, SVD, closed form; r1 and r2 normalized separately
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
    V = np.vstack([intrinsic_constraints(H) for H in Hs])
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
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
    sign = 1.0 if A[2, 2] > 0 else -1.0
    n1, n2 = np.linalg.norm(A[:, 0]), np.linalg.norm(A[:, 1])
    r1, r2 = sign * A[:, 0] / n1, sign * A[:, 1] / n2
    t = sign * A[:, 2] / n1
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, 2] *= -1
        R = U @ Vt
    return R, t
