# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: hartley_eigh
# formulation: Hartley sqrt(2) mean distance, eigenvector of A^T A (eigh)
import math

import numpy as np


def apply_homography(H, pts):
    p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    ph = np.concatenate([p, np.ones((p.shape[0], 1))], axis=1)
    q = np.einsum("ij,nj->ni", np.asarray(H, dtype=np.float64), ph)
    return q[:, :2] / q[:, 2][:, None]

def _normalizer(p):
    c = p.mean(axis=0)
    s = math.sqrt(2) / np.mean(np.linalg.norm(p - c, axis=1))
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])

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
    H = np.linalg.solve(Td, h.reshape(3, 3) @ Ts)
    return H / H[2, 2]
