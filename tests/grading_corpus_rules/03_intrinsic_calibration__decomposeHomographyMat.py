# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.decomposeHomographyMat computes extrinsics_from_homography
# charged: extrinsics_from_homography
# expect: calls cv2.decomposeHomographyMat, which does the exercise for you


import cv2
import numpy as np


def extrinsics_from_homography(K, H):
    n, Rs, ts, normals = cv2.decomposeHomographyMat(np.asarray(H, float), np.asarray(K, float))
    A = np.linalg.inv(np.asarray(K, float)) @ np.asarray(H, float)
    lam = 1.0 / np.linalg.norm(A[:, 0])
    lam = -lam if A[2, 2] < 0 else lam
    return Rs[0], lam * A[:, 2]
