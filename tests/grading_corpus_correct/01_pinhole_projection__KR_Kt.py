# Correct implementation, written differently, for tests/test_grading_fairness.py: must get full marks.
# variant: KR_Kt
# formulation: K R and K t premultiplied, homogeneous division by w

import numpy as np


def project_points(K, R, t, X):
    KR = np.asarray(K, float) @ np.asarray(R, float)
    Kt = np.asarray(K, float) @ np.asarray(t, float).reshape(3)
    uvw = np.asarray(X, float).reshape(-1, 3) @ KR.T + Kt
    w = uvw[:, 2]
    return np.column_stack([uvw[:, 0] / w, uvw[:, 1] / w])
