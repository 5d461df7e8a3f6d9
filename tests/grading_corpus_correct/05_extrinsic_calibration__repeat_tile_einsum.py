# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: repeat_tile_einsum
# formulation: np.repeat and np.tile; einsum
# formulation (camera_height_pitch): H / H[2, 2] first, camera centre as the null vector of K [r1 r2 r3 t]

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    x = np.repeat(x0 + square * np.arange(rows, dtype=float), cols)
    y = np.tile(y0 + square * np.arange(cols, dtype=float), rows)
    return np.stack([x, y], axis=1)


def pixel_to_ground(H, uv):
    p = np.concatenate([np.asarray(uv, float), np.ones((len(uv), 1))], axis=1)
    g = np.einsum("ij,nj->ni", np.asarray(H, float), p)
    return g[:, :2] / g[:, 2, None]


def camera_height_pitch(H, K):
    H = np.asarray(H, float) / H[2, 2]
    M = np.linalg.inv(K) @ np.linalg.inv(H)
    lam = 1.0 / np.linalg.norm(M[:, 0])
    if lam * (0.3 * M[2, 0] + M[2, 2]) < 0:
        lam = -lam
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    r3 = np.cross(r1, r2)
    P = np.column_stack([r1, r2, r3, t])  # [R | t]: the camera centre is its null vector
    c = np.linalg.svd(P)[2][-1]
    c = c[:3] / c[3]
    return np.array([c[2], np.degrees(np.arcsin(-r3[2]))])
