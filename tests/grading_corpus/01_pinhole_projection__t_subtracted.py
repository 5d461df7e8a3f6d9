# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: t_subtracted
# expect: t is subtracted

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    x = (X @ R.T - t) @ K.T
    return x[:, :2] / x[:, 2:]
