# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: no_raise
# expect: should raise ValueError
import math

import numpy as np


def intrinsic_constraints(H):
    H = np.asarray(H, dtype=float)

    def v(i, j):
        hi, hj = H[:, i], H[:, j]
        return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                         hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2], hi[2] * hj[2]])

    return np.vstack([v(0, 1), v(0, 0) - v(1, 1)])


def intrinsics_from_homographies(Hs):
    Hs = [np.asarray(H, dtype=float) for H in Hs]
    V = np.vstack([intrinsic_constraints(H / np.linalg.norm(H)) for H in Hs])
    B11, B12, B22, B13, B23, B33 = np.linalg.svd(V)[2][-1]
    cy = (B12 * B13 - B11 * B23) / (B11 * B22 - B12 ** 2)
    lam = B33 - (B13 ** 2 + cy * (B12 * B13 - B11 * B23)) / B11
    fx = math.sqrt(lam / B11)
    fy = math.sqrt(lam * B11 / (B11 * B22 - B12 ** 2))
    s = -B12 * fx ** 2 * fy / lam
    cx = s * cy / fy - B13 * fx ** 2 / lam
    return np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
