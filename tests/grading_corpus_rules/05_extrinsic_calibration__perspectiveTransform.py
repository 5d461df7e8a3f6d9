# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.perspectiveTransform computes pixel_to_ground
# charged: pixel_to_ground
# expect: calls cv2.perspectiveTransform, which does the exercise for you

import cv2
import numpy as np


def pixel_to_ground(H, uv):
    return cv2.perspectiveTransform(np.asarray(uv, float).reshape(-1, 1, 2), np.asarray(H, float)).reshape(-1, 2)
