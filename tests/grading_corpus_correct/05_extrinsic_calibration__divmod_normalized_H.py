# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: divmod_normalized_H
# formulation: divmod; H / H[2, 2] written out
# formulation (camera_height_pitch): lambda = 1 / |K^-1 h1|, nearest rotation by SVD, pitch asin(-R[2, 2])

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    out = np.zeros((cols * rows, 2))
    for k in range(cols * rows):
        j, i = divmod(k, cols)
        out[k] = x0 + square * j, y0 + square * i
    return out


def pixel_to_ground(H, uv):
    H = np.asarray(H, float)
    H = H / H[2, 2]  # any scale: dividing by H[2, 2] changes nothing
    uv = np.asarray(uv, float)
    w = H[2, 0] * uv[:, 0] + H[2, 1] * uv[:, 1] + H[2, 2]
    return np.column_stack([(H[0, 0] * uv[:, 0] + H[0, 1] * uv[:, 1] + H[0, 2]) / w,
                            (H[1, 0] * uv[:, 0] + H[1, 1] * uv[:, 1] + H[1, 2]) / w])


def camera_height_pitch(H, K):
    import math

    M = np.linalg.inv(K) @ np.linalg.inv(H)
    lam = 1.0 / np.linalg.norm(M[:, 0])
    if lam * (0.3 * M[2, 0] + M[2, 2]) < 0:
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    U, _, Wt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ Wt
    C = -R.T @ t
    return np.array([C[2], math.degrees(math.asin(-R[2, 2]))])
