# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: meshgrid_rows
# formulation: meshgrid; rows @ H.T
# formulation (camera_height_pitch): normalized separately: r1 and r2 each divided by its own norm

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    ys, xs = np.meshgrid(y0 + square * np.arange(cols), x0 + square * np.arange(rows))
    return np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)


def pixel_to_ground(H, uv):
    uv = np.asarray(uv, float).reshape(-1, 2)
    g = np.column_stack([uv, np.ones(len(uv))]) @ np.asarray(H, float).T
    return g[:, :2] / g[:, 2:]


def camera_height_pitch(H, K):
    M = np.linalg.inv(K) @ np.linalg.inv(H)
    if (M[:, 2] + 0.3 * M[:, 0])[2] < 0:
        M = -M
    s = 1.0 / np.linalg.norm(M[:, 0])
    r1 = M[:, 0] / np.linalg.norm(M[:, 0])
    r2 = M[:, 1] / np.linalg.norm(M[:, 1])
    t = s * M[:, 2]
    R = np.stack([r1, r2, np.cross(r1, r2)], axis=1)
    height = -(R[:, 2] @ t)
    pitch = np.degrees(np.arcsin(-R[2, 2]))
    return np.array([height, pitch], dtype=np.float64)
