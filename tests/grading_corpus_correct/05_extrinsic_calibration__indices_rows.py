# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: indices_rows
# formulation: np.indices; rows @ H.T
# formulation (camera_height_pitch): lambda from the mean of both columns, r3 = r1 x r2 as is, optical axis atan2

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    j, i = np.indices((int(rows), int(cols)), dtype=np.float64)
    return np.column_stack([(x0 + square * j).ravel(), (y0 + square * i).ravel()])


def pixel_to_ground(H, uv):
    uv = np.asarray(uv, float).reshape(-1, 2)
    g = np.column_stack([uv, np.ones(len(uv))]) @ np.asarray(H, float).T
    return g[:, :2] / g[:, 2:]


def camera_height_pitch(H, K):
    M = np.linalg.solve(K, np.linalg.inv(H))
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    if (0.25 * r1 + t)[2] < 0:
        r1, r2, t = -r1, -r2, -t
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    axis = R[2]  # the optical axis in the robot frame
    return np.array([float(-(R.T @ t)[2]), float(np.degrees(np.arctan2(-axis[2], np.hypot(axis[0], axis[1]))))])
