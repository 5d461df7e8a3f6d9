# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: abs_pitch
# expect: abs() on the pitch

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    k = np.arange(cols * rows)
    return np.column_stack([x0 + (k // cols) * square, y0 + (k % cols) * square]).astype(float)


def pixel_to_ground(H, uv):
    p = np.column_stack([uv, np.ones(len(uv))]) @ np.asarray(H, float).T
    return p[:, :2] / p[:, 2:]


def camera_height_pitch(H, K):
    M = np.linalg.inv(K) @ np.linalg.inv(H)
    lam = 1.0 / np.linalg.norm(M[:, 0])
    if lam * (0.3 * M[2, 0] + M[2, 2]) < 0:
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Wt
    C = -R.T @ t
    return np.array([C[2], abs(np.degrees(np.arcsin(-R[2, 2])))])  # "a pitch is an angle, so it is positive"
