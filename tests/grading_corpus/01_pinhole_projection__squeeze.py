# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: squeeze
# expect: should have shape (1, 2)

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    x = (X @ R.T + t) @ K.T
    return np.squeeze(x[:, :2] / x[:, 2:])
