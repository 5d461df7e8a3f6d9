# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.undistortPoints computes undistort_normalized; rectification_maps, through a helper of its own that is
# not an exercise, calls cv2.projectPoints and is charged for it
# charged: undistort_normalized, rectification_maps
# expect: calls cv2.undistortPoints, which does the exercise for you

import cv2
import numpy as np


def undistort_normalized(xy_d, dist):
    pts = np.asarray(xy_d, float).reshape(-1, 1, 2)
    return cv2.undistortPoints(pts, np.eye(3), np.asarray(dist, float),
                               criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)).reshape(-1, 2)


def _lens(xy, dist):
    X = np.column_stack([xy, np.ones(len(xy))])
    return cv2.projectPoints(X, np.zeros(3), np.zeros(3), np.eye(3), np.asarray(dist, float))[0].reshape(-1, 2)


def rectification_maps(K, dist, new_K, size):
    K = np.asarray(K, float)
    w, h = int(size[0]), int(size[1])
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)]).astype(float)
    rays = np.linalg.inv(np.asarray(new_K, float)) @ pix
    xy = _lens((rays[:2] / rays[2]).T, dist)
    uv = np.column_stack([xy, np.ones(len(xy))]) @ K.T
    return uv[:, 0].reshape(h, w).astype(np.float32), uv[:, 1].reshape(h, w).astype(np.float32)
