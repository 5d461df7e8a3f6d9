# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: normalized_first
# formulation: normalized coordinates first, then fx, s, cx, fy, cy

import numpy as np


def project_points(K, R, t, X):
    Xc = (np.asarray(R, float) @ np.asarray(X, float).T).T + np.asarray(t, float).reshape(1, 3)
    x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    fx, s, cx, fy, cy = K[0][0], K[0][1], K[0][2], K[1][1], K[1][2]
    return np.stack([fx * x + s * y + cx, fy * y + cy], axis=1).astype(np.float64)
