# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: einsum
# formulation: einsum for R X + t and for K, np.divide

import numpy as np


def project_points(K, R, t, X):
    Xc = np.einsum("ij,nj->ni", np.asarray(R, dtype=np.float64), np.asarray(X, dtype=np.float64)) + np.ravel(t)
    x = np.einsum("ij,nj->ni", np.asarray(K, dtype=np.float64), Xc)
    return np.divide(x[:, :2], x[:, [2]])
