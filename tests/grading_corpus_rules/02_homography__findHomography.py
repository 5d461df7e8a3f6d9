# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.findHomography computes estimate_homography
# charged: estimate_homography
# expect: calls cv2.findHomography, which does the exercise for you

import cv2
import numpy as np


def estimate_homography(src, dst):
    H = cv2.findHomography(np.asarray(src, float), np.asarray(dst, float), 0)[0]
    return H / H[2, 2]
