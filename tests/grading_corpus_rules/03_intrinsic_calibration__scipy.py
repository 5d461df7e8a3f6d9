# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: SciPy is not allowed in any notebook (numpy.linalg has everything): the polar decomposition and the
# spectral norm by scipy.linalg are refused with the grader's words
# charged: extrinsics_from_homography
# expect: not allowed: extrinsics_from_homography uses scipy.linalg.polar


import numpy as np
import scipy.linalg


def extrinsics_from_homography(K, H):
    A = np.linalg.inv(np.asarray(K, float)) @ np.asarray(H, float)
    lam = 1.0 / np.linalg.norm(A[:, 0])
    if A[2, 2] < 0:
        lam = -lam
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    R = scipy.linalg.polar(np.column_stack([r1, r2, np.cross(r1, r2)]))[0]
    return R, t
