# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: no_division
# expect: no division in pixel_to_ground

import numpy as np


def pixel_to_ground(H, uv):
    uv = np.asarray(uv, dtype=float)
    H = np.asarray(H, dtype=float)
    p = np.column_stack([uv, np.ones(len(uv))]) @ H.T
    return p[:, :2]
