# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: hartley_svd_calls_apply
# formulation: Hartley sqrt(2) mean distance, SVD; normalizes with its own apply_homography
import math

import numpy as np


def apply_homography(H, pts):
    p = np.asarray(pts, float).reshape(-1, 2)
    q = np.column_stack([p, np.ones(len(p))]) @ np.asarray(H, float).T
    return q[:, :2] / q[:, 2:]

def _normalizer(p):
    c = p.mean(axis=0)
    s = math.sqrt(2) / np.mean(np.linalg.norm(p - c, axis=1))
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
    h = np.linalg.svd(A)[2][-1]
    H = np.linalg.inv(Td) @ h.reshape(3, 3) @ Ts
    return H / H[2, 2]
