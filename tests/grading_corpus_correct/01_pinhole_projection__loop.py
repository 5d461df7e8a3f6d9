# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: loop
# formulation: one point at a time with Python floats

import numpy as np


def project_points(K, R, t, X):
    K, R, t = np.asarray(K, float), np.asarray(R, float), np.asarray(t, float).reshape(3)
    out = np.empty((len(X), 2))
    for i, p in enumerate(np.asarray(X, float)):
        xc = R @ p + t
        x, y = xc[0] / xc[2], xc[1] / xc[2]
        out[i] = [K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]]
    return out
