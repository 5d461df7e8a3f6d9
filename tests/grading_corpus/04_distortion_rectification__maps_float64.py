# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: maps_float64
# expect: wrong dtype

import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, dtype=float)
    k1, k2, p1, p2, k3 = dist
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([xd, yd])


def rectification_maps(K, dist, new_K, size):
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
    rays = np.linalg.inv(new_K) @ pix
    xy_d = distort_normalized((rays[:2] / rays[2]).T, dist)
    map_x = K[0, 0] * xy_d[:, 0] + K[0, 1] * xy_d[:, 1] + K[0, 2]
    map_y = K[1, 1] * xy_d[:, 1] + K[1, 2]
    return map_x.reshape(h, w), map_y.reshape(h, w)
