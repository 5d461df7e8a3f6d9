# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: pitch_radians
# expect: the pitch is in radians

import numpy as np


def camera_height_pitch(H, K):
    M = np.linalg.inv(K) @ np.linalg.inv(H)
    lam = 1.0 / np.linalg.norm(M[:, 0])
    if lam * (0.3 * M[2, 0] + M[2, 2]) < 0:
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Wt
    C = -R.T @ t
    return np.array([C[2], np.arcsin(-R[2, 2])])
