# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: from_left
# expect: corners starting from the left

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    pts = []
    for i in range(rows):
        for j in reversed(range(cols)):
            pts.append([x0 + i * square, y0 + j * square])
    return np.array(pts, dtype=float)
