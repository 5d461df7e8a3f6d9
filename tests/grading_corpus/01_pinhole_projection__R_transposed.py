# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: R_transposed
# expect: R is transposed

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    x = (X @ R + t) @ K.T
    return x[:, :2] / x[:, 2:]
