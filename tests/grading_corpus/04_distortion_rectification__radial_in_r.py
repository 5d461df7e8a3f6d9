# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: radial_in_r
# expect: radial terms in r instead of r^2

import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, dtype=float)
    k1, k2, p1, p2, k3 = dist
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    r = np.sqrt(r2)
    radial = 1 + k1 * r + k2 * r ** 2 + k3 * r ** 3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([xd, yd])
