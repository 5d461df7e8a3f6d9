# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: plain_numeric_loop
# formulation: plain distortion, numerical-Jacobian Newton, maps row by row

import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    k1, k2, p1, p2, k3 = np.asarray(dist, dtype=np.float64).ravel()[:5]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x ** 2 + y ** 2
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    return np.column_stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x ** 2),
                            y * radial + p1 * (r2 + 2 * y ** 2) + 2 * p2 * x * y])


def undistort_normalized(xy_d, dist):
    xy_d = np.asarray(xy_d, float).reshape(-1, 2)
    xy = xy_d.copy()
    h = 1e-7
    for _ in range(60):
        f = distort_normalized(xy, dist) - xy_d
        if np.max(np.abs(f), initial=0.0) < 1e-14:
            break
        fx = (distort_normalized(xy + [h, 0], dist) - distort_normalized(xy - [h, 0], dist)) / (2 * h)
        fy = (distort_normalized(xy + [0, h], dist) - distort_normalized(xy - [0, h], dist)) / (2 * h)
        det = fx[:, 0] * fy[:, 1] - fy[:, 0] * fx[:, 1]
        xy = xy - np.column_stack([(fy[:, 1] * f[:, 0] - fy[:, 0] * f[:, 1]) / det,
                                   (fx[:, 0] * f[:, 1] - fx[:, 1] * f[:, 0]) / det])
    return xy


def rectification_maps(K, dist, new_K, size):
    w, h = int(size[0]), int(size[1])
    K, nKi = np.asarray(K, float), np.linalg.inv(np.asarray(new_K, float))
    map_x = np.empty((h, w), np.float32)
    map_y = np.empty((h, w), np.float32)
    us = np.arange(w, dtype=float)
    for v in range(h):
        rays = np.column_stack([us, np.full(w, float(v)), np.ones(w)]) @ nKi.T
        xy = distort_normalized(rays[:, :2] / rays[:, 2:], dist)
        p = np.column_stack([xy, np.ones(w)]) @ K.T
        map_x[v], map_y[v] = p[:, 0], p[:, 1]
    return map_x, map_y
