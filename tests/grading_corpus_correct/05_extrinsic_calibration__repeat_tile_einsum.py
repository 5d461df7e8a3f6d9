# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: repeat_tile_einsum
# formulation: np.repeat and np.tile; einsum

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    x = np.repeat(x0 + square * np.arange(rows, dtype=float), cols)
    y = np.tile(y0 + square * np.arange(cols, dtype=float), rows)
    return np.stack([x, y], axis=1)


def pixel_to_ground(H, uv):
    p = np.concatenate([np.asarray(uv, float), np.ones((len(uv), 1))], axis=1)
    g = np.einsum("ij,nj->ni", np.asarray(H, float), p)
    return g[:, :2] / g[:, 2, None]
