# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_exercise_rules.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: cv2.initUndistortRectifyMap computes rectification_maps (notebook 04 says it is forbidden)
# charged: rectification_maps
# expect: calls cv2.initUndistortRectifyMap, which does the exercise for you

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
    xy_d = np.asarray(xy_d, dtype=np.float64).reshape(-1, 2)
    k1, k2, p1, p2, k3 = np.asarray(dist, dtype=np.float64).ravel()[:5]
    xy = xy_d.copy()
    for _ in range(100):
        f = distort_normalized(xy, dist) - xy_d
        if np.abs(f).max(initial=0.0) < 1e-14:
            break
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        rho = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        drho = k1 + 2 * k2 * r2 + 3 * k3 * r2 ** 2
        J = np.empty((len(xy), 2, 2))
        J[:, 0, 0] = rho + 2 * x * x * drho + 2 * p1 * y + 6 * p2 * x
        J[:, 0, 1] = J[:, 1, 0] = 2 * x * y * drho + 2 * p1 * x + 2 * p2 * y
        J[:, 1, 1] = rho + 2 * y * y * drho + 6 * p1 * y + 2 * p2 * x
        xy = xy - np.linalg.solve(J, f[:, :, None])[:, :, 0]
    return xy
def rectification_maps(K, dist, new_K, size):
    return cv2.initUndistortRectifyMap(np.asarray(K, float), np.asarray(dist, float), None, np.asarray(new_K, float),
                                       (int(size[0]), int(size[1])), cv2.CV_32FC1)
