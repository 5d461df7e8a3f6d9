# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: loops_columns
# formulation: two loops; H @ columns

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    pts = []
    for j in range(int(rows)):
        for i in range(int(cols)):
            pts.append((x0 + j * square, y0 + i * square))
    return np.array(pts, dtype=np.float64)


def pixel_to_ground(H, uv):
    H = np.asarray(H, dtype=np.float64)
    p = np.vstack([np.asarray(uv, dtype=np.float64).T, np.ones(len(uv))])
    g = H @ p
    return (g[:2] / g[2]).T.copy()
