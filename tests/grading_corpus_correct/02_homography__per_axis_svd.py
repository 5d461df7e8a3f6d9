# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: per_axis_svd
# formulation: per-axis standardization (mean 0, std 1 on each axis), SVD

import numpy as np


def apply_homography(H, pts):
    p = np.asarray(pts, float).reshape(-1, 2)
    q = np.column_stack([p, np.ones(len(p))]) @ np.asarray(H, float).T
    return q[:, :2] / q[:, 2:]

def _normalizer(p):
    c, sd = p.mean(axis=0), p.std(axis=0)
    return np.array([[1 / sd[0], 0, -c[0] / sd[0]], [0, 1 / sd[1], -c[1] / sd[1]], [0, 0, 1.0]])

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
    H = np.linalg.solve(Td, h.reshape(3, 3)) @ Ts
    return H / H[2, 2]
