# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: H_transposed
# expect: H is transposed
import math

import numpy as np


def apply_homography(H, pts):
    pts = np.asarray(pts, dtype=float)
    p = np.column_stack([pts, np.ones(len(pts))]) @ np.asarray(H, dtype=float).T
    return p[:, :2] / p[:, 2:3]


def estimate_homography(src, dst):
    src = np.asarray(src, dtype=float)
    dst = np.asarray(dst, dtype=float)

    def normalize(p):
        c = p.mean(axis=0)
        s = math.sqrt(2) / np.mean(np.linalg.norm(p - c, axis=1))
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])

    Ts, Td = normalize(src), normalize(dst)
    a, b = apply_homography(Ts, src), apply_homography(Td, dst)

    rows = []
    for (x, y), (u, v) in zip(a, b):
        rows.append([-x, -y, -1, 0, 0, 0, u * x, u * y, u])
        rows.append([0, 0, 0, -x, -y, -1, v * x, v * y, v])
    Hn = np.linalg.svd(np.array(rows))[2][-1].reshape(3, 3).T
    H = np.linalg.inv(Td) @ Hn @ Ts
    return H / H[2, 2]
