# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: per_axis_eigh
# formulation: per-axis standardization, eigh of A^T A

import numpy as np


def apply_homography(H, pts):
    H = np.asarray(H, float)
    p = np.asarray(pts, float).reshape(-1, 2).T
    q = H[:, :2] @ p + H[:, 2:3]
    return (q[:2] / q[2]).T.copy()

def _normalizer(p):
    c, sd = p.mean(axis=0), p.std(axis=0)
    return np.array([[1 / sd[0], 0, -c[0] / sd[0]], [0, 1 / sd[1], -c[1] / sd[1]], [0, 0, 1.0]])

def estimate_homography(src, dst):
    src = np.asarray(src, float).reshape(-1, 2)
    dst = np.asarray(dst, float).reshape(-1, 2)
    Ts, Td = _normalizer(src), _normalizer(dst)
    s = src @ Ts[:2, :2].T + Ts[:2, 2]
    d = dst @ Td[:2, :2].T + Td[:2, 2]
    A = []
    for (x, y), (u, v) in zip(s, d):
        A.append([x, y, 1, 0, 0, 0, -u * x, -u * y, -u])
        A.append([0, 0, 0, x, y, 1, -v * x, -v * y, -v])
    A = np.array(A)
    h = np.linalg.eigh(A.T @ A)[1][:, 0]
    H = np.linalg.inv(Td) @ h.reshape(3, 3) @ Ts
    return H / H[2, 2]
