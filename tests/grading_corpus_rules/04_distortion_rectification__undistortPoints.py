# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_exercise_rules.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.undistortPoints computes undistort_normalized; rectification_maps, through a helper of its own that is
# not an exercise, calls cv2.projectPoints and is charged for it
# charged: undistort_normalized, rectification_maps
# expect: calls cv2.undistortPoints, which does the exercise for you

import cv2
import numpy as np


def distort_normalized(xy, dist):
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    k1, k2, p1, p2, k3 = np.asarray(dist, dtype=np.float64).ravel()[:5]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x ** 2 + y ** 2
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    return np.column_stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x ** 2),
                            y * radial + p1 * (r2 + 2 * y ** 2) + 2 * p2 * x * y])


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
