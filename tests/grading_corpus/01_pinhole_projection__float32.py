# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: float32
# expect: of dtype float64, got dtype float32

import numpy as np


def project_points(K, R, t, X):
    X = np.asarray(X, dtype=float)
    x = ((X @ R.T + t) @ K.T).astype(np.float32)
    return x[:, :2] / x[:, 2:]
