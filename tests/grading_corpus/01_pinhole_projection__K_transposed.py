# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: K_transposed
# expect: K is transposed

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    x = (X @ R.T + t) @ K
    return x[:, :2] / x[:, 2:]
