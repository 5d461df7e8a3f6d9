# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: modifies_input
# expect: changed its input

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    X = np.asarray(X)
    X -= 0.0
    X += t @ R  # shift into the camera frame in place
    x = (X @ R.T) @ K.T
    return x[:, :2] / x[:, 2:]
