# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: projection_matrix
# formulation: P = K [R | t] applied to homogeneous points, then divided

import numpy as np


def project_points(K, R, t, X):
    P = np.asarray(K, float) @ np.column_stack([np.asarray(R, float), np.reshape(t, 3)])
    Xh = np.column_stack([np.asarray(X, float), np.ones(len(X))])
    x = Xh @ P.T
    return x[:, :2] / x[:, 2:]
