# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: meshgrid_rows
# formulation: meshgrid; rows @ H.T

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    ys, xs = np.meshgrid(y0 + square * np.arange(cols), x0 + square * np.arange(rows))
    return np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)


def pixel_to_ground(H, uv):
    uv = np.asarray(uv, float).reshape(-1, 2)
    g = np.column_stack([uv, np.ones(len(uv))]) @ np.asarray(H, float).T
    return g[:, :2] / g[:, 2:]
