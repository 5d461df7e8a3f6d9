# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.projectPoints computes the exercise
# charged: project_points
# expect: calls cv2.projectPoints, which does the exercise for you

import cv2
import numpy as np


def project_points(K, R, t, X):
    rvec = cv2.Rodrigues(np.asarray(R, float))[0]
    X = np.asarray(X, float)
    return cv2.projectPoints(X, rvec, np.asarray(t, float), np.asarray(K, float), None)[0].reshape(-1, 2)
