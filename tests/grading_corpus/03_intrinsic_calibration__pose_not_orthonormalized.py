# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: not_orthonormalized
# expect: R is not orthonormalized

import numpy as np


def extrinsics_from_homography(K, H):
    A = np.linalg.inv(K) @ H
    lam = 1.0 / np.linalg.norm(A[:, 0])
    if A[2, 2] * lam < 0:
        lam = -lam
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    R = np.column_stack([r1, r2, np.cross(r1, r2)])

    return R, t
