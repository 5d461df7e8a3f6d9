# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: skew_dropped
# expect: skew s = K[0, 1] is dropped

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    Xc = X @ R.T + t
    u = K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 2]
    v = K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]
    return np.column_stack([u, v])
