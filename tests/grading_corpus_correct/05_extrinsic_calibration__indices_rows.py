# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: indices_rows
# formulation: np.indices; rows @ H.T

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    j, i = np.indices((int(rows), int(cols)), dtype=np.float64)
    return np.column_stack([(x0 + square * j).ravel(), (y0 + square * i).ravel()])


def pixel_to_ground(H, uv):
    uv = np.asarray(uv, float).reshape(-1, 2)
    g = np.column_stack([uv, np.ones(len(uv))]) @ np.asarray(H, float).T
    return g[:, :2] / g[:, 2:]
