# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: column_order
# expect: corners in column order

import numpy as np


def board_ground_points(cols, rows, square, x0, y0):
    pts = []
    for j in range(cols):
        for i in range(rows):
            pts.append([x0 + i * square, y0 + j * square])
    return np.array(pts, dtype=float)
