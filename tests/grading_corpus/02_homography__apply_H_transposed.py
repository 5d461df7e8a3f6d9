# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: H_transposed
# expect: H is transposed

import numpy as np


def apply_homography(H, pts):
    pts = np.asarray(pts, dtype=float)
    H = np.asarray(H, dtype=float)
    p = np.column_stack([pts, np.ones(len(pts))]) @ H
    return p[:, :2] / p[:, 2:3]
