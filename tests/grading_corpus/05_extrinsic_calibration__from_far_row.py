# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: from_far_row
# expect: corners starting from the far row

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    pts = []
    for i in reversed(range(rows)):
        for j in range(cols):
            pts.append([x0 + i * square, y0 + j * square])
    return np.array(pts, dtype=float)
