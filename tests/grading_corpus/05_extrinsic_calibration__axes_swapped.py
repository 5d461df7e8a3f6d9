# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: axes_swapped
# expect: ground axes swapped

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    pts = []
    for i in range(rows):
        for j in range(cols):
            pts.append([y0 + j * square, x0 + i * square])
    return np.array(pts, dtype=float)
