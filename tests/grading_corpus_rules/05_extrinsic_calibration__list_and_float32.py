# Corpus of the rule table (dtscal_lib/exercise_rules.py) for tests/test_grading_fairness.py: the self-check and the
# grader agree on every function (self-check passes <=> full marks); the charged functions lose points in both.
# rule: a list returned (camera_height_pitch) is refused with the same words as every other function's; float32
# arithmetic inside pixel_to_ground fails the precision contract
# charged: pixel_to_ground, camera_height_pitch
# expect: got a list: return numpy arrays

import numpy as np


def pixel_to_ground(H, uv):
    uv = np.asarray(uv, np.float32).reshape(-1, 2)
    g = np.column_stack([uv, np.ones(len(uv), np.float32)]) @ np.asarray(H, np.float32).T
    return (g[:, :2] / g[:, 2:]).astype(np.float64)


def camera_height_pitch(H, K):
    M = np.linalg.solve(K, np.linalg.inv(H))
    lam = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    if (0.25 * r1 + t)[2] < 0:
        r1, r2, t = -r1, -r2, -t
    R = np.column_stack([r1, r2, np.cross(r1, r2)])
    axis = R[2]
    return [float(-(R.T @ t)[2]), float(np.degrees(np.arctan2(-axis[2], np.hypot(axis[0], axis[1]))))]
