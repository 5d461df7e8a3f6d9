# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.initUndistortRectifyMap computes rectification_maps (notebook 04 says it is forbidden)
# charged: rectification_maps
# expect: calls cv2.initUndistortRectifyMap, which does the exercise for you

import cv2
import numpy as np


def rectification_maps(K, dist, new_K, size):
    return cv2.initUndistortRectifyMap(np.asarray(K, float), np.asarray(dist, float), None, np.asarray(new_K, float),
                                       (int(size[0]), int(size[1])), cv2.CV_32FC1)
