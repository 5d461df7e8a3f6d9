# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: uv_swapped
# expect: u and v are swapped

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    x = (X @ R.T + t) @ K.T
    return np.column_stack([x[:, 1] / x[:, 2], x[:, 0] / x[:, 2]])
