# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: loops_columns
# formulation: two loops; H @ columns
# formulation (camera_height_pitch): geometric mean of the two column norms, the centre from solving R C = -t

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


def camera_height_pitch(H, K):
    import math

    G = np.linalg.inv(np.asarray(H, float))
    M = np.linalg.inv(np.asarray(K, float)) @ G
    lam = 1.0 / math.sqrt(np.linalg.norm(M[:, 0]) * np.linalg.norm(M[:, 1]))
    if (lam * M[:, 2] + 0.3 * lam * M[:, 0])[2] <= 0:
        lam = -lam
    r1 = lam * M[:, 0]
    r2 = lam * M[:, 1]
    r3 = np.cross(r1, r2)
    R = np.column_stack([r1, r2, r3])
    C = np.linalg.solve(R, -lam * M[:, 2])
    return np.array([C[2], math.degrees(math.asin(-r3[2]))])
