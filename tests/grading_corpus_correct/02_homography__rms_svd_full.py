# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: rms_svd_full
# formulation: sqrt(2) RMS distance, full SVD (minimal 4 points: 8 x 9 A)
import math

import numpy as np


def apply_homography(H, pts):
    H = np.asarray(H, float)
    p = np.asarray(pts, float).reshape(-1, 2).T
    q = H[:, :2] @ p + H[:, 2:3]
    return (q[:2] / q[2]).T.copy()

def _normalizer(p):
    c = p.mean(axis=0)
    s = math.sqrt(2.0 / np.mean(np.sum((p - c) ** 2, axis=1)))
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])

def estimate_homography(src, dst):
    src = np.asarray(src, float).reshape(-1, 2)
    dst = np.asarray(dst, float).reshape(-1, 2)
    Ts, Td = _normalizer(src), _normalizer(dst)
    s = apply_homography(Ts, src)
    d = apply_homography(Td, dst)
    A = []
    for (x, y), (u, v) in zip(s, d):
        A.append([x, y, 1, 0, 0, 0, -u * x, -u * y, -u])
        A.append([0, 0, 0, x, y, 1, -v * x, -v * y, -v])
    A = np.array(A)
    U, S, Vt = np.linalg.svd(A, full_matrices=True)
    h = Vt[np.argmin(np.r_[S, np.zeros(9 - len(S))])] if len(S) < 9 else Vt[-1]
    H = np.linalg.inv(Td) @ h.reshape(3, 3) @ Ts
    return H / H[2, 2]
