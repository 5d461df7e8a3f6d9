# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: distort_pixel_offsets
# expect: the lens polynomial was evaluated on pixel-sized numbers

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
    # distortion applied to pixel offsets from the principal point, not to normalized coordinates
    d = distort_normalized(np.column_stack([u.ravel() - new_K[0, 2], v.ravel() - new_K[1, 2]]), dist)
    map_x = d[:, 0] + K[0, 2]
    map_y = d[:, 1] + K[1, 2]
    return map_x.reshape(h, w).astype(np.float32), map_y.reshape(h, w).astype(np.float32)
