# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: tangential_swapped
# expect: tangential terms swapped

import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, dtype=float)
    k1, k2, p1, p2, k3 = dist
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2 * p2 * x * y + p1 * (r2 + 2 * x * x)
    yd = y * radial + p2 * (r2 + 2 * y * y) + 2 * p1 * x * y
    return np.column_stack([xd, yd])
